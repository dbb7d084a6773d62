"""The house rules of ``sim/`` (see docs/architecture.md): layers import downwards only,
``mjcf`` and ``hydraulics`` import nothing from ``sim``, ``sim/calibrate`` has no import
cycle, only ``sim/papers`` names a
table, no module grows past 800 lines and no function past 100 (outside a short list,
each entry with its reason), and sources are cited by the keys of docs/references.md."""

import ast
import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: rank of each layer: a module may import its own layer or lower ones, never higher.
LAYERS = {
    "sim.errors": 0,
    "sim.validate": 0,
    "sim.parallel": 0,
    "sim.signals": 0,
    "sim.scenario": 1,
    "sim.effects": 2,
    "sim.control": 2,
    "sim.loop": 3,
    "sim.runs": 4,
    "sim.assess": 5,
    "sim.identify": 5,
    "sim.calibrate": 6,
    "sim.sweep": 7,
    "sim.papers": 8,
    "sim.report": 9,
    "sim.cli": 10,
    "sim.__main__": 10,
}
TABLE_NAMES = {"cgs", "rice", "ucsd"}


def _modules(pkg: str):
    for path in sorted((ROOT / pkg).rglob("*.py")):
        yield ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__"), path


def _imports(path: Path):
    """Every module imported anywhere in the file (function-local imports too)."""
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield a.name, node.lineno
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            yield node.module, node.lineno
            for a in node.names:  # "from sim.loop import _kernels" imports sim.loop._kernels
                yield f"{node.module}.{a.name}", node.lineno


def _layer(module: str):
    best = None
    for name, rank in LAYERS.items():
        if module == name or module.startswith(name + "."):
            best = rank
    return best


def test_every_sim_module_belongs_to_a_layer():
    stray = [m for m, _ in _modules("sim") if m != "sim" and _layer(m) is None]
    assert not stray, f"modules outside the layers of LAYERS: {stray}"


def test_imports_go_downwards_only():
    bad = []
    for mod, path in _modules("sim"):
        own = _layer(mod)
        if own is None:
            continue
        for imp, line in _imports(path):
            other = _layer(imp)
            if other is not None and other > own:
                bad.append(f"{path.relative_to(ROOT)}:{line} ({mod}, layer {own}) imports {imp} (layer {other})")
    assert not bad, "upward imports:\n" + "\n".join(bad)


def _import_graph(pkg: str) -> dict:
    """module -> the modules of ``pkg`` it imports (function-local imports too); ``from
    a.b import c`` names the submodule ``a.b.c`` when there is one, else ``a.b``."""
    mods = dict(_modules(pkg))
    graph = {}
    for mod, path in mods.items():
        deps = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                deps |= {a.name for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                subs = {f"{node.module}.{a.name}" for a in node.names}
                deps |= subs if subs <= mods.keys() else subs | {node.module}
        graph[mod] = {d for d in deps if d in mods and d != mod}
    return graph


def _cycle(graph: dict) -> list:
    """One import cycle of ``graph`` (a list of modules, the first repeated last), or []."""
    state: dict = {}

    def visit(m, trail):
        state[m] = "open"
        for d in sorted(graph[m]):
            if state.get(d) == "open":
                return trail[trail.index(d) :] + [d]
            if d not in state and (found := visit(d, trail + [d])):
                return found
        state[m] = "done"
        return []

    for m in sorted(graph):
        if m not in state and (found := visit(m, [m])):
            return found
    return []


def test_the_calibration_modules_import_one_another_without_a_cycle():
    """sim/calibrate is layered inside too: the search loop (engine), the paths' steps
    (mechsearch, pathsearch), stages and search above the pieces they share."""
    found = _cycle(_import_graph("sim/calibrate"))
    assert not found, "import cycle: " + " -> ".join(found)
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": set()}) == []


@pytest.mark.parametrize("pkg", ["mjcf", "hydraulics"])
def test_model_layers_import_nothing_from_sim(pkg):
    bad = [
        f"{p.relative_to(ROOT)}:{line} imports {imp}"
        for _, p in _modules(pkg)
        for imp, line in _imports(p)
        if imp == "sim" or imp.startswith("sim.")
    ]
    assert not bad, bad


def test_only_papers_name_a_table():
    """Generic code dispatches on declared fields, never on a table's name."""
    bad = []
    for pkg in ("sim", "mjcf", "hydraulics"):
        for mod, path in _modules(pkg):
            if mod.startswith("sim.papers"):
                continue
            tree = ast.parse(path.read_text())
            docstrings = {
                id(n.body[0].value)
                for n in ast.walk(tree)
                if isinstance(n, (ast.Module, ast.FunctionDef, ast.ClassDef, ast.AsyncFunctionDef))
                and n.body
                and isinstance(n.body[0], ast.Expr)
                and isinstance(n.body[0].value, ast.Constant)
            }
            for node in ast.walk(tree):
                if (
                    isinstance(node, ast.Constant)
                    and isinstance(node.value, str)
                    and id(node) not in docstrings
                    and node.value.strip().lower() in TABLE_NAMES
                ):
                    bad.append(f"{path.relative_to(ROOT)}:{node.lineno} names table '{node.value}'")
    assert not bad, "\n".join(bad)


def test_no_module_over_800_lines():
    long = [
        f"{p.relative_to(ROOT)}: {n}"
        for pkg in ("sim", "mjcf", "hydraulics")
        for _, p in _modules(pkg)
        if (n := len(p.read_text().splitlines())) > 800
    ]
    assert not long, long


#: the internal codes the papers once had ("seed" and three digits); docs/references.md
#: gives their keys ([Airouche 2014], [Trombetti 2002], [Ozcelik 2008]).
OLD_SOURCE_CODE = re.compile(r"seeds?[ -]0{2}", re.IGNORECASE)


def _tracked_text_files():
    """The project's tracked files that read as UTF-8 text (git's list; without git, every
    file under the root outside hidden and build folders)."""
    try:
        out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
        paths = [ROOT / n for n in out.decode().split("\0") if n]
    except (OSError, subprocess.CalledProcessError):
        skip = {"build", "dist", "__pycache__", "node_modules"}
        paths = [
            p
            for p in ROOT.rglob("*")
            if not any(part.startswith(".") or part in skip for part in p.relative_to(ROOT).parts)
        ]
    for p in paths:
        if p.is_file() and not p.is_symlink():
            try:
                yield p, p.read_text(encoding="utf-8")
            except UnicodeDecodeError:
                continue  # a figure or other binary file


def test_sources_are_cited_by_key_not_by_internal_code():
    """A reader outside the project cannot look up an internal code: cite the paper's key."""
    bad = [
        f"{p.relative_to(ROOT)}:{i}: {line.strip()[:100]}"
        for p, text in _tracked_text_files()
        for i, line in enumerate(text.splitlines(), 1)
        if OLD_SOURCE_CODE.search(line)
    ]
    assert not bad, "cite docs/references.md's keys instead:\n" + "\n".join(bad)


#: the longest a function may be, in lines (def to last line, docstring included)
FUNCTION_LINES = 100
#: functions still over the limit, each with its reason; an entry is removed when its
#: function is split (the test below fails on a stale entry, so the list only shrinks).
LONG_FUNCTIONS = {
    "hydraulics/_kernel.py::step_loops": "compiled kernel: numba keeps the ~40 per-actuator scalars of the "
    "valve, supply and chamber steps in one loop body; the same steps are named functions in the numpy "
    "backend (hydraulics/_numpy_step.py), which test_backends_agree holds it to",
}


def _functions(path: Path):
    """(qualified name, lines) of every function and method in the file, nested ones too."""

    def walk(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                yield prefix + child.name, child.end_lineno - child.lineno + 1
                yield from walk(child, prefix + child.name + ".")
            elif isinstance(child, ast.ClassDef):
                yield from walk(child, prefix + child.name + ".")
            else:
                yield from walk(child, prefix)

    yield from walk(ast.parse(path.read_text()), "")


def _function_lengths():
    for pkg in ("sim", "mjcf", "hydraulics", "bench"):
        for _, path in _modules(pkg):
            for name, n in _functions(path):
                yield f"{path.relative_to(ROOT).as_posix()}::{name}", n


def test_no_function_over_100_lines():
    """One idea per function: a new function over the limit fails here; the ones that
    remain are listed in LONG_FUNCTIONS with their reason."""
    long = {name: n for name, n in _function_lengths() if n > FUNCTION_LINES}
    new = [f"{name}: {n} lines" for name, n in sorted(long.items()) if name not in LONG_FUNCTIONS]
    assert not new, f"functions over {FUNCTION_LINES} lines (split them along their steps):\n" + "\n".join(new)
    stale = [name for name in LONG_FUNCTIONS if name not in long]
    assert not stale, f"split or gone, remove from LONG_FUNCTIONS: {stale}"


def test_the_function_length_check_sees_methods_and_nested_functions(tmp_path):
    """The walk names methods by their class and measures every function."""
    src = tmp_path / "m.py"
    src.write_text(
        "class A:\n    def f(self):\n        def g():\n            pass\n        return 1\n\n\ndef h():\n    pass\n"
    )
    assert dict(_functions(src)) == {"A.f": 4, "A.f.g": 2, "h": 2}


def test_test_files_have_unique_names():
    """The tests folders are not packages, so pytest imports each test file by its base
    name: two files of one name stop the whole run at collection ("import file
    mismatch"; tests/loop/test_engine.py and a new tests/calibrate/test_engine.py did)."""
    seen: dict[str, Path] = {}
    for p in sorted((ROOT / "tests").rglob("test_*.py")):
        assert p.name not in seen, f"{p.relative_to(ROOT)} and {seen[p.name].relative_to(ROOT)} share a name"
        seen[p.name] = p
