"""A campaign from its file to its summary: what has been done is read back (the folder, then the
store), only the rest is run on the cluster, and the summary, the Parquet file and the HTML
report are written from every result in run order."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .ledger import Ledger, recover_from_store
from .spec import Campaign
from .summary import NOT_MEASURED, MeasurementSummary, counts, summarise


@dataclass
class CampaignOutcome:
    """What a campaign invocation did and found."""

    campaign: Campaign
    runs: int  # the runs asked for (all, or the first N)
    results: list[dict[str, Any]]  # every result, in run order
    summary: list[MeasurementSummary]
    counts: dict[str, int]
    ran: list[str] = field(default_factory=list)  # run ids made by this invocation
    skipped: int = 0  # runs already done (folder or store)
    running_elsewhere: list[str] = field(default_factory=list)
    files: dict[str, str] = field(default_factory=dict)
    dashboard: str = ""

    def as_json(self) -> dict[str, Any]:
        return {"campaign": self.campaign.id, "runs": self.runs, "ran": len(self.ran),
                "ran_ids": sorted(self.ran),
                "skipped": self.skipped, "running_elsewhere": self.running_elsewhere, "counts": self.counts,
                "summary": [s.as_dict() for s in self.summary], "files": self.files,
                "failed": [{"run_id": r["run_id"], "outcome": r["outcome"],
                            "error": r.get("error") or r.get("end_reason")}
                           for r in self.results if r["outcome"] in NOT_MEASURED]}


def run_campaign(campaign: Campaign, *, runs_dir: str, results_url: str | None, out_dir: str | Path,
                 scheduler: str | None = None, workers: int | None = None, retry_failed: bool = False,
                 show: bool = True, on_dashboard: Any = None, first: int | None = None) -> CampaignOutcome:
    """Run what is left of a campaign (or of its `first` runs) and summarise all of it (of them)."""
    from .dispatch import dashboard, dask_client, run_all

    if results_url and "://" not in results_url:  # a SQLite file: the same one from any worker's folder
        results_url = str(Path(results_url).resolve())
    ledger = Ledger(out_dir, campaign)
    runs = [r.as_dict() for r in campaign.runs()][:first]
    done = ledger.results()
    if retry_failed:
        done = {k: v for k, v in done.items() if v["outcome"] not in NOT_MEASURED}
    todo = [r for r in runs if r["run_id"] not in done]
    running: list[str] = []
    if todo:  # killed after the store took a run but before its result was kept
        from bench.results import ResultsStore

        store = ResultsStore(results_url, offline_ok=True)
        try:
            found, running = recover_from_store(store, todo)
        finally:
            store.close()
        for result in found:
            if retry_failed and result["outcome"] in NOT_MEASURED:
                continue
            ledger.record(result)
            done[result["run_id"]] = result
        todo = [r for r in todo if r["run_id"] not in done and r["run_id"] not in running]
    outcome = CampaignOutcome(campaign, len(runs), [], [], {}, skipped=len(runs) - len(todo) - len(running),
                              running_elsewhere=running)
    if todo:
        with dask_client(scheduler, workers) as client:
            outcome.dashboard = dashboard(client)
            if on_dashboard is not None:
                on_dashboard(outcome.dashboard)
            operator = f"campaign {campaign.id}"
            for result in run_all(client, todo, str(Path(runs_dir).resolve()), results_url, ledger.record,
                                  operator=operator, show=show):
                done[result["run_id"]] = result
                outcome.ran.append(result["run_id"])
    outcome.results = sorted((done[r["run_id"]] for r in runs if r["run_id"] in done), key=lambda r: r["index"])
    outcome.summary = summarise(outcome.results, campaign.measurements, campaign.band)
    outcome.counts = counts(outcome.results)
    outcome.files = write_outputs(outcome, Path(out_dir))
    return outcome


def write_outputs(outcome: CampaignOutcome, folder: Path) -> dict[str, str]:
    """summary.json, runs.parquet and report.html in the campaign's folder; their paths."""
    from .outputs import write_html, write_parquet

    files = {"summary": folder / "summary.json", "parquet": folder / "runs.parquet", "report": folder / "report.html"}
    files["summary"].write_text(json.dumps({"campaign": outcome.campaign.id, "counts": outcome.counts,
                                            "summary": [s.as_dict() for s in outcome.summary]}, indent=1))
    write_parquet(outcome.results, files["parquet"])
    write_html(outcome.results, outcome.summary, files["report"], f"Campaign {outcome.campaign.id}", outcome.counts)
    return {k: str(v) for k, v in files.items()}
