"""The layer order of docs/architecture.md, read from the code's own imports (the standard library's
`ast`; every import statement counts, at module level, inside a function or under TYPE_CHECKING):
no import circle anywhere in the package, and no import against the layer order.  A failure names
the file, the line and the name imported."""

from __future__ import annotations

import ast
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("bench", "drivers", "procedures", "simulators")

#: the layers, bottom first: a module may import its own layer and those below.  A module belongs to
#: the layer of the longest prefix listed ("name=" matches that module alone); docs/architecture.md
#: says what each layer holds and why.
LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("contracts", ("bench.validation", "bench.devices", "bench.streams", "bench.fault_kinds", "bench.clock",
                   "bench.numbers", "bench.figures", "bench.figure_layout", "bench.pdf", "bench.nominal",
                   "bench.analysis",
                   "bench.kernel_cache", "bench=")),
    ("devices", ("drivers", "simulators")),
    ("engine", ("bench.engine", "bench.station", "bench.station_config", "bench.slots", "bench.recorder",
                "bench.compaction", "bench.writer", "bench.results", "bench.progress", "bench.composition")),
    ("procedures", ("procedures", "bench.line")),
    ("faces", ("bench.cli", "bench.campaign", "bench.gui", "bench.reporting", "bench.report", "bench.pytest_plugin",
               "bench.line.cli", "bench.line.fpga_cli", "bench.line.report")),
)
#: the only modules outside simulators/ that may import a simulator: the composition root, which
#: builds simulated stations; the line's simulated lot, which draws its units (simulators.lot); and
#: the pytest plugin's simulated-world fixture
SIMULATOR_USERS = ("bench.composition", "bench.line.simulate", "bench.pytest_plugin")
#: what simulators may take from the drivers: the protocol modules they share (frames, registers,
#: command spellings), never a driver
PROTOCOL_MODULES = ("drivers.fpga.protocol", "drivers.rate_table.modbus_protocol",
                    "drivers.rate_table.ascii_protocol", "drivers.rate_table.acutronic_protocol",
                    "drivers.chamber.watlow_f4_protocol", "drivers.frontend.commands", "drivers.errors")


@dataclass(frozen=True)
class Import:
    source: str  # the importing module
    target: str  # the module imported (the longest known module the name resolves to)
    path: Path
    line: int
    text: str  # the name as written


def modules() -> dict[str, Path]:
    found = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            found[".".join(parts)] = path
    return found


def _resolve(name: str, known: dict[str, Path]) -> str | None:
    while name and name not in known:
        name = name.rpartition(".")[0]
    return name or None


def imports(known: dict[str, Path]) -> list[Import]:
    out = []
    for module, path in known.items():
        package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names = [(a.name, a.name) for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    base = ".".join(package[: len(package) - node.level + 1] + ([node.module] if node.module else []))
                names = [(f"{base}.{a.name}", f"{base}.{a.name}" if node.level == 0 else a.name) for a in node.names]
            else:
                continue
            for full, text in names:
                target = _resolve(full, known)
                if target and target != module:
                    out.append(Import(module, target, path.relative_to(ROOT), node.lineno, text))
    return out


def layer_of(module: str) -> int:
    best, best_len = None, -1
    for rank, (_, prefixes) in enumerate(LAYERS):
        for prefix in prefixes:
            exact = prefix.endswith("=")
            prefix = prefix.rstrip("=")
            hit = module == prefix or (not exact and module.startswith(prefix + "."))
            if hit and len(prefix) > best_len:
                best, best_len = rank, len(prefix)
    assert best is not None, f"{module}: in no layer of tests/test_layers.py LAYERS (add it where it belongs)"
    return best


def _within(module: str, prefixes: tuple[str, ...]) -> bool:
    return any(module == p or module.startswith(p + ".") for p in prefixes)


def violations(found: list[Import]) -> list[str]:
    """Every import against the layer order, one line each."""
    bad = []
    for imp in found:
        src, dst = imp.source, imp.target
        where = f"{imp.path}:{imp.line}: {src} imports {imp.text}"
        if layer_of(dst) > layer_of(src):
            bad.append(f"{where} ({LAYERS[layer_of(src)][0]} -> {LAYERS[layer_of(dst)][0]}: upward)")
        if _within(dst, ("simulators",)) and not _within(src, ("simulators", *SIMULATOR_USERS)):
            bad.append(f"{where} (only {', '.join(SIMULATOR_USERS)} may use a simulator)")
        if _within(src, ("drivers",)) and _within(dst, ("simulators",)):
            bad.append(f"{where} (a driver never imports a simulator)")
        if _within(src, ("simulators",)) and _within(dst, ("drivers",)) and not _within(dst, PROTOCOL_MODULES):
            bad.append(f"{where} (a simulator takes only the drivers' protocol modules)")
        if _within(src, ("bench.reporting",)) and _within(dst, ("procedures",)) and dst != "procedures":
            bad.append(f"{where} (the report never imports a procedure: it asks the registry, `procedures`)")
    return bad


def circles(found: list[Import]) -> list[list[str]]:
    """The import circles (strongly connected components of more than one module), Tarjan's way."""
    graph: dict[str, set[str]] = defaultdict(set)
    for imp in found:
        graph[imp.source].add(imp.target)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def _edges_in(circle: list[str], found: list[Import]) -> list[str]:
    members = set(circle)
    return [f"  {i.path}:{i.line}: {i.source} imports {i.text}" for i in found
            if i.source in members and i.target in members]


def test_the_package_has_no_import_circle():
    found = imports(modules())
    report = [f"circle {' <-> '.join(c)}:\n" + "\n".join(_edges_in(c, found)) for c in circles(found)]
    assert not report, "import circles:\n" + "\n".join(report)


def test_every_import_follows_the_layer_order():
    bad = violations(imports(modules()))
    assert not bad, "imports against the layer order (docs/architecture.md):\n" + "\n".join(bad)


def test_every_module_has_a_layer():
    for module in modules():
        layer_of(module)


def test_the_checks_catch_what_they_are_for(tmp_path):
    """The rules themselves: an upward import, a simulator imported by the engine and a circle are
    each reported with the file and the name."""
    p = Path("x.py")
    up = Import("drivers.fpga.link", "bench.engine.context", p, 3, "bench.engine.context.GuardedClock")
    sim = Import("bench.engine.runner", "simulators.world", p, 4, "simulators.world.World")
    rep = Import("bench.reporting", "procedures.hrg_damping", p, 5, "procedures.hrg_damping.WINDOWS")
    bad = violations([up, sim, rep])
    assert any("x.py:3" in b and "upward" in b and "GuardedClock" in b for b in bad)
    assert any("x.py:4" in b and "may use a simulator" in b for b in bad)
    assert any("x.py:5" in b and "never imports a procedure" in b for b in bad)
    loop = [Import("a", "b", p, 1, "b"), Import("b", "a", p, 2, "a")]
    assert circles(loop) == [["a", "b"]]
