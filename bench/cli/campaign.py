"""`gyrobench campaign FILE.toml`: many simulated runs as one study on a Dask cluster, resumable,
summarised (docs/campaigns.md)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from .common import EXIT_BAD_OUTCOME, EXIT_OK, EXIT_USAGE, CliError, _check_runs_dir, _err


def add_parser(sub) -> None:
    """Register `campaign` and its options."""
    p = sub.add_parser("campaign", help="run a study of many simulated runs (a campaign TOML file) on Dask")
    p.add_argument("file", help="the campaign file (docs/campaigns.md)")
    p.add_argument("--scheduler", default=None, metavar="tcp://HOST:8786",
                   help="an existing Dask cluster's scheduler (default: a LocalCluster on this machine)")
    p.add_argument("--workers", type=int, default=None, help="LocalCluster worker processes (default: the cores)")
    p.add_argument("--results", default=None, help="results store URL or SQLite file (default: the station's)")
    p.add_argument("--runs-dir", default=None,
                   help="directory of the raw files, shared by every worker (default: the station's)")
    p.add_argument("--out", default=None, help="the campaign's folder (default: RUNS_DIR/campaigns/ID)")
    p.add_argument("--first", type=int, default=None, metavar="N",
                   help="only the study's first N runs (a later run without it makes the rest)")
    p.add_argument("--retry-failed", action="store_true", help="run again the runs that failed before")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(func=cmd)


def cmd(args: argparse.Namespace) -> int:
    from bench.campaign.core import run_campaign
    from bench.campaign.outputs import summary_table
    from bench.campaign.spec import CampaignError, load_campaign
    from bench.devices import StationError
    from bench.station_config import load_config

    try:
        campaign = load_campaign(args.file)
        config = load_config(campaign.station)
    except (CampaignError, StationError, OSError) as exc:
        _err(str(exc))
        return EXIT_USAGE
    if config.simulation is None:
        _err(f"campaign {campaign.id}: station {campaign.station!r} is real; a campaign runs simulated units")
        return EXIT_USAGE
    if args.workers is not None and args.workers < 1:
        raise CliError(f"--workers {args.workers}: at least 1")
    if args.first is not None and args.first < 1:
        raise CliError(f"--first {args.first}: at least 1")
    runs_dir = args.runs_dir or config.station["runs_dir"]
    _check_runs_dir(runs_dir)
    out = Path(args.out) if args.out else Path(runs_dir) / "campaigns" / campaign.id
    results_url = args.results or config.station["results"]
    show = not args.json and sys.stderr.isatty()

    def say(link: str) -> None:
        print(f"dashboard: {link}", file=sys.stderr)

    outcome = run_campaign(campaign, runs_dir=runs_dir, results_url=results_url, out_dir=out,
                           scheduler=args.scheduler, workers=args.workers, retry_failed=args.retry_failed,
                           show=show, on_dashboard=say, first=args.first)
    if args.json:
        print(json.dumps(outcome.as_json()))
    else:
        from rich.console import Console

        n = outcome.runs
        console = Console(width=None if sys.stdout.isatty() else 140)  # a pipe keeps whole numbers
        console.print(f"campaign {campaign.id}: {n} runs, {len(outcome.ran)} run now, {outcome.skipped} done before; "
                      + ", ".join(f"{k} {v}" for k, v in outcome.counts.items()))
        if outcome.summary:
            console.print(summary_table(outcome.summary, f"campaign {campaign.id}"))
        else:
            console.print("  no measurement with a truth to summarise (the Parquet file holds every value)")
        for key, path in outcome.files.items():
            console.print(f"  {key} {path}")
    for run_id in outcome.running_elsewhere:
        _err(f"run {run_id} is still running elsewhere (its store row is RUNNING): run the campaign again after it")
    failed = [r for r in outcome.results if r["outcome"] in ("ERROR", "ABORTED", "INTERRUPTED")]
    for r in failed[:5]:
        _err(f"run {r['run_id']} {r['outcome']}: {r.get('error') or r.get('end_reason')}")
    if len(failed) > 5:
        _err(f"... and {len(failed) - 5} more failed runs (the report lists them)")
    complete = len(outcome.results) == outcome.runs
    return EXIT_OK if complete and not failed else EXIT_BAD_OUTCOME
