"""Spin the table at a rate, hold it there, and check the rate the table reports."""

from bench.engine import Param, Procedure, Result, step


class TableSpin(Procedure):
    """Spin the table and check its reported rate against the command."""

    name = "table-spin"
    requires = ("table",)
    rate_dps = Param(100.0, unit="deg/s", low=-1000.0, high=1000.0, doc="table rate")
    hold_s = Param(2.0, unit="s", low=0.1, high=600.0, doc="time held at rate")
    tolerance_dps = Param(0.5, unit="deg/s", low=0.01, high=10.0, doc="allowed rate error")

    @step("Spin up")
    def spin_up(self, ctx):
        table = ctx.devices.table
        table.enable()
        table.set_rate(self.rate_dps)
        table.wait_at_rate(tolerance_dps=0.1, stable_for_s=0.2, timeout_s=60.0)

    @step("Hold at rate")
    def hold(self, ctx):
        rates = []
        for k in range(10):
            ctx.sleep(self.hold_s / 10)  # bench clock: virtual time on a simulated station
            rates.append(ctx.devices.table.status().rate_dps)
            ctx.progress((k + 1) / 10, f"{rates[-1]:.3f} deg/s")
        mean = sum(rates) / len(rates)
        tol = self.tolerance_dps
        ctx.measure("table_rate_dps", mean, "deg/s", limits=(self.rate_dps - tol, self.rate_dps + tol))

    def analysis(self, data):
        """Re-fit of a recorded run (`gyrobench analyze RUN`): mean of the table readings at rate."""
        rate = data.table("table")["rate_dps"]
        tol = self.tolerance_dps
        at_rate = rate[abs(rate - self.rate_dps) < 0.1 * tol]  # settled readings only
        limits = (self.rate_dps - tol, self.rate_dps + tol)
        return [Result("table_rate_dps", float(at_rate.mean()), "deg/s", limits=limits)]
