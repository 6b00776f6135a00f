"""Campaigns: many simulated runs as one study (docs/campaigns.md).  A face above the procedures:
a TOML file (bench.campaign.spec) expands into normal runs made on dask.distributed workers
(bench.campaign.dispatch, bench.campaign.execute), kept in a resumable folder
(bench.campaign.ledger) and summarised (bench.campaign.summary, bench.campaign.outputs);
bench.campaign.core ties them together."""
