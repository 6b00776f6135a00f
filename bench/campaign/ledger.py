"""What a campaign has done, on disk: its folder holds `campaign.json` (the id, the study's
fingerprint, the number of runs) and one `results/<run id>.json` a finished run, written whole
(a temporary file renamed) when the run comes back.  A restarted campaign runs only what has no
result here and no finished row in the store: a killed campaign resumes, nothing runs twice."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from .spec import Campaign, CampaignError

#: store outcomes of a run that is not finished (RUNNING: still going somewhere; INTERRUPTED: its
#: process died, so it runs again under the same id)
UNFINISHED = ("RUNNING", "INTERRUPTED")


class Ledger:
    """A campaign's folder of results."""

    def __init__(self, folder: str | Path, campaign: Campaign) -> None:
        self.dir = Path(folder)
        self.results_dir = self.dir / "results"
        self.results_dir.mkdir(parents=True, exist_ok=True)
        head = {"id": campaign.id, "fingerprint": campaign.fingerprint, "source": campaign.source,
                "runs": len(campaign.runs())}
        path = self.dir / "campaign.json"
        if path.exists():
            old = json.loads(path.read_text())
            if old.get("fingerprint") != campaign.fingerprint:
                raise CampaignError(
                    f"{campaign.source}: campaign id {campaign.id!r} already names another study in {self.dir} "
                    f"(fingerprint {old.get('fingerprint')} != {campaign.fingerprint}): give this one another id")
        else:
            self._write(path, head)

    @staticmethod
    def _write(path: Path, doc: dict[str, Any]) -> None:
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps(doc, sort_keys=True))
        os.replace(tmp, path)

    def record(self, result: dict[str, Any]) -> None:
        """Keep one run's result (a failed run's too, with its error)."""
        self._write(self.results_dir / f"{result['run_id']}.json", result)

    def results(self) -> dict[str, dict[str, Any]]:
        """Every result kept, by run id."""
        out = {}
        for path in sorted(self.results_dir.glob("*.json")):
            try:
                doc = json.loads(path.read_text())
            except (OSError, ValueError):
                continue  # a result the kill cut short: the run is made again
            out[doc["run_id"]] = doc
        return out


def recover_from_store(store: Any, runs: list[dict[str, Any]]) -> tuple[list[dict[str, Any]], list[str]]:
    """Results of runs the store holds finished though the folder has none (the campaign was killed
    between the store's row and the result file), and the ids of runs still RUNNING elsewhere."""
    from .execute import result_from_row

    found, running = [], []
    for run in runs:
        try:
            row = store.get_run(run["run_id"])
        except KeyError:
            continue
        if row["run_id"] != run["run_id"]:
            continue  # a prefix of another id: not this run
        if row["outcome"] == "RUNNING":
            running.append(run["run_id"])
        elif row["outcome"] not in UNFINISHED:
            found.append(result_from_row(run, row))
    return found, running
