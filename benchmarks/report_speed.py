"""Benchmark: the report of a default `hrg-damping` run (1108 s of bench time: 900 s decay, two
90 s drift records; about 300,000 FPGA rows) renders in under 3 s.

Times `gyrobench report RUN` as a user runs it (a fresh process: imports, HDF5 read, matplotlib
figures as SVG, Jinja2 page), the in-process render alone, and the PDF (WeasyPrint) for the record.

Run: .venv/bin/python benchmarks/report_speed.py [RAW.h5]   (default: records a seed-0 run first)
"""

from __future__ import annotations

import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TARGET_S = 3.0


def record_run(runs_dir: str) -> Path:
    from bench.composition.sim_station import SimStation
    from bench.engine import Runner
    from procedures.hrg_damping import HrgDamping

    station = SimStation("sim-hrg", seed=0).open()
    try:
        return Path(Runner(station, runs_dir=runs_dir).run(HrgDamping, {}).raw_file)
    finally:
        station.close()


def main() -> None:
    tmp = tempfile.mkdtemp(prefix="gyrobench-report-")
    raw = Path(sys.argv[1]) if len(sys.argv) > 1 else record_run(tmp)
    from bench.recorder import open_run

    with open_run(raw) as data:
        sim_s, rows = data.attrs.get("simulated_s"), len(data.array("fpga"))
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; run {raw.name}: "
          f"{sim_s:.0f} s of bench time, {rows} FPGA rows")

    cli, cpu = [], []
    for k in range(3):
        t0, r0 = time.perf_counter(), resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run([sys.executable, "-m", "bench.cli", "report", str(raw), "-o", f"{tmp}/r{k}.html"], check=True,
                       capture_output=True)
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        cli.append(time.perf_counter() - t0)
        cpu.append(r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime)  # what a machine to itself would take
    from bench.pdf import write_pdf
    from bench.reporting import render_html

    inproc = []
    with open_run(raw) as data:
        for _ in range(3):
            t0 = time.perf_counter()
            html = render_html(data)
            inproc.append(time.perf_counter() - t0)
    t0, c0 = time.perf_counter(), time.process_time()
    write_pdf(html, f"{tmp}/r.pdf")
    pdf_s, pdf_cpu = time.perf_counter() - t0, time.process_time() - c0
    med = statistics.median(cli)
    print(f"gyrobench report RUN (fresh process): median {med:.2f} s of {', '.join(f'{x:.2f}' for x in cli)}"
          f"  -> {'OK' if med < TARGET_S else 'TOO SLOW'} (target < {TARGET_S:g} s)")
    print(f"  CPU time of that process (user + system; less sensitive to other jobs): median "
          f"{statistics.median(cpu):.2f} s of {', '.join(f'{x:.2f}' for x in cpu)}")
    print(f"render_html in process: median {statistics.median(inproc):.2f} s; page {len(html) / 1e6:.2f} MB")
    print(f"PDF (WeasyPrint) of the page: {pdf_s:.2f} s ({pdf_cpu:.2f} s CPU), "
          f"{Path(f'{tmp}/r.pdf').stat().st_size / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
