"""Spin the table at a rate, hold it there, and check the rate the table reports."""

from bench.engine import Demand, Measurement, Param, Procedure, Result, step
from bench.streams import Column, StreamSchema, declare

HOLD = declare(StreamSchema("hold", "table-spin", (Column("t_s", "s", quantity="time t"),
                                                    Column("rate_dps", "deg/s", quantity="table rate Ω"))))


class TableSpin(Procedure):
    """Spin the table and check its reported rate against the command."""

    name = "table-spin"
    requires = ("table",)
    uses_compute = False  # no `ctx.compute`: a run need not start the compute workers' forkserver
    rate_dps = Param(100.0, unit="deg/s", low=-1000.0, high=1000.0, doc="table rate")
    hold_s = Param(2.0, unit="s", low=0.1, high=600.0, doc="time held at rate")
    tolerance_dps = Param(0.5, unit="deg/s", low=0.01, high=10.0, doc="allowed rate error")

    measurements = (
        Measurement("table_rate_dps", "deg/s", "mean of the rates the table reports while held at the command",
                    truth=None, limits=lambda p: (p.rate_dps - p.tolerance_dps, p.rate_dps + p.tolerance_dps)),
    )

    def demands(self):
        """Checked against the station's limits before the table is enabled."""
        return [Demand("table", "max_rate_dps", "rate_dps", self.rate_dps, "deg/s")]

    @step("Spin up")
    def spin_up(self, ctx):
        table = ctx.devices.table
        table.enable()
        table.set_rate(self.rate_dps)
        table.wait_at_rate(tolerance_dps=0.1, stable_for_s=0.2, timeout_s=60.0)

    @step("Hold at rate")
    def hold(self, ctx):
        for k in range(10):
            ctx.sleep(self.hold_s / 10)  # bench clock: virtual time on a simulated station
            status = ctx.devices.table.status()
            ctx.record(HOLD, HOLD.names, [[ctx.clock.now(), status.rate_dps]])  # raw data, on disk
            ctx.progress((k + 1) / 10, f"{status.rate_dps:.3f} deg/s")
        for result in self.analysis(ctx.data()):
            ctx.report(result)

    def analysis(self, data):
        """The measurement from the recorded readings: the same code live and in
        `gyrobench analyze RUN`."""
        rate = data.table("hold")["rate_dps"]
        mean = float(rate.mean())
        if len(rate) < 2:
            return [Result("table_rate_dps", mean)]  # unit and limits: the declaration
        from scipy import special  # stdtrit is what stats.t.ppf calls, without importing scipy.stats (~0.4 s)

        half = float(special.stdtrit(len(rate) - 1, 0.975) * rate.std(ddof=1) / len(rate) ** 0.5)
        return [Result("table_rate_dps", mean, ci95=(mean - half, mean + half))]  # of the mean of the readings

    def figures(self, data) -> list:
        """The figures this run's results need (procedures.figures.table_spin): the report and
        `gyrobench analyze --figures` draw these."""
        from procedures.figures.table_spin import figures

        return figures(self, data)
