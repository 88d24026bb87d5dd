"""The package layering and the web-free core, checked on the real import graph."""

import ast
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ORDER = ["sim", "recorder", "metrics", "sessions", "dashboard"]


def imported_packages(package: str) -> set[str]:
    found = set()
    for path in (ROOT / package).rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                found.update(alias.name.split(".")[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                found.add(node.module.split(".")[0])
    return found


def test_imports_point_one_way():
    for level, package in enumerate(ORDER):
        higher = set(ORDER[level + 1 :])
        assert not imported_packages(package) & higher, f"{package} imports a higher layer"


def modules_loaded_by(imports: str, watched: tuple[str, ...]) -> list[str]:
    """Which of ``watched`` a fresh interpreter has loaded after ``import {imports}``."""
    code = f"import sys; import {imports}; print(','.join(m for m in {watched!r} if m in sys.modules))"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return [m for m in result.stdout.strip().split(",") if m]


def test_core_imports_without_the_web_or_rendering_stack():
    heavy = ("vtk", "pyvista", "cv2", "OpenImageIO", "fastapi", "starlette", "sqlalchemy")
    assert (
        modules_loaded_by("sim, sim.mesh, sim.fem, sim.calibration.indentation, recorder, metrics", heavy)
        == []
    )


def test_the_command_line_package_loads_no_web_module():
    """Issue 24: `sessions.cli` (every command but `serve`) imports no web framework."""
    web = ("fastapi", "starlette", "uvicorn", "jinja2", "dashboard")
    assert modules_loaded_by("sessions, sessions.cli", web) == []


def test_each_command_is_registered_where_its_module_says():
    """Issue 24: every command of `vascsim` is registered explicitly; `serve` by the console script."""
    from dashboard.cli import main as console
    from sessions.cli import main

    assert console is main and console.commands["serve"].callback.__module__ == "dashboard.cli"
    for name, command in main.commands.items():
        expected = "dashboard.cli" if name == "serve" else "sessions.cli."
        assert command.callback.__module__.startswith(expected), name


FRONT_ENDS = ("sessions/cli/", "dashboard/")
CLI_ADVICE = re.compile(r"`vascsim|(^|\s)--[a-z]")


def raised_messages(path: Path):
    """(line, the string parts of the message) of every ``raise Error(...)`` in a module."""
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Raise) and isinstance(node.exc, ast.Call):
            parts = [
                c.value
                for argument in node.exc.args
                for c in ast.walk(argument)
                if isinstance(c, ast.Constant) and isinstance(c.value, str)
            ]
            yield node.lineno, "".join(parts)


def test_library_errors_carry_no_command_line_advice():
    """A library's message names what is wrong; what to run is the CLI's to say (from the error's
    ``remedy``), so the dashboard never tells a supervisor to pass a flag."""
    advising = [
        f"{path.relative_to(ROOT)}:{line}"
        for package in ORDER
        for path in (ROOT / package).rglob("*.py")
        if not str(path.relative_to(ROOT)).startswith(FRONT_ENDS)
        for line, message in raised_messages(path)
        if CLI_ADVICE.search(message)
    ]
    assert advising == []


def test_each_front_end_says_a_remedy_in_its_own_words():
    from dashboard.errors import said
    from sessions.catalog import AlreadyExists, WrongState
    from sessions.cli.base import remedy_in_words

    rated = AlreadyExists("'sup' already rated session S-1 with GRS", remedy=("replace-rating", "S-1"))
    assert remedy_in_words(rated) == "; pass --replace to replace that rating"
    assert "Replace my earlier rating" in said(rated) and "--replace" not in said(rated)
    assert said(rated, api=True).endswith('send "replace": true')
    unscored = WrongState("study 'course' has no scored sessions", remedy=("score", "course"))
    assert remedy_in_words(unscored) == "; run `vascsim score --study course` first"
    assert said(WrongState("plain")) == "plain" and remedy_in_words(WrongState("plain")) == ""


# -- the size of things (issue 48): a file a newcomer can read, a folder they can scan ----------------
MAX_FILE_LINES = 500
MAX_FOLDER_MODULES = 15
FOLDERS_OF_ONE_MODULE_PER_COMMAND = ("sessions/cli",)
# Not yet split: each may shrink, none may grow, and a file or folder split under the limit leaves
# this list (the test says so), so the list only ever gets shorter.
FILES_TO_SPLIT: dict[str, int] = {}
FOLDERS_TO_SPLIT: dict[str, int] = {}


def python_files():
    for package in ORDER:
        yield from sorted((ROOT / package).rglob("*.py"))


def test_no_file_is_over_the_line_limit():
    sizes = {path.relative_to(ROOT).as_posix(): len(path.read_text().splitlines()) for path in python_files()}
    over = {name: lines for name, lines in sizes.items() if lines > MAX_FILE_LINES}
    grown = {name: lines for name, lines in over.items() if lines > FILES_TO_SPLIT.get(name, MAX_FILE_LINES)}
    assert not grown, f"over {MAX_FILE_LINES} lines (split them; see docs/architecture.md): {grown}"
    split = sorted(set(FILES_TO_SPLIT) - set(over))
    assert not split, f"now within {MAX_FILE_LINES} lines: take {split} off FILES_TO_SPLIT"


def test_no_folder_holds_more_than_fifteen_modules():
    folders = {path.parent for path in python_files()}
    counts = {
        folder.relative_to(ROOT).as_posix(): len(list(folder.glob("*.py")))
        for folder in folders
        if folder.relative_to(ROOT).as_posix() not in FOLDERS_OF_ONE_MODULE_PER_COMMAND
    }
    over = {name: n for name, n in counts.items() if n > MAX_FOLDER_MODULES}
    grown = {name: n for name, n in over.items() if n > FOLDERS_TO_SPLIT.get(name, MAX_FOLDER_MODULES)}
    assert not grown, f"over {MAX_FOLDER_MODULES} modules (make a sub-package for one idea): {grown}"
    split = sorted(set(FOLDERS_TO_SPLIT) - set(over))
    assert not split, f"now within {MAX_FOLDER_MODULES} modules: take {split} off FOLDERS_TO_SPLIT"


CATALOG = "sessions/catalog/"
SQL_BUILDERS = {"select", "insert", "update", "delete", "func", "text"}
"""SQLAlchemy's statement builders: whoever imports one writes a query."""


def sql_writers() -> set[str]:
    """Modules outside the catalog's folder that import a statement builder from SQLAlchemy."""
    found = set()
    for path in python_files():
        name = path.relative_to(ROOT).as_posix()
        if name.startswith(CATALOG):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("sqlalchemy"):
                if SQL_BUILDERS & {alias.name for alias in node.names}:
                    found.add(name)
            elif isinstance(node, ast.Attribute) and node.attr in SQL_BUILDERS:
                if isinstance(node.value, ast.Name) and node.value.id in ("sqlalchemy", "sa"):
                    found.add(name)
    return found


def test_queries_are_written_only_in_the_catalog():
    writers = sorted(sql_writers())
    assert not writers, (
        f"queries belong in {CATALOG} (the store, the engine or a query module), not in {writers}"
    )


def first_party_modules() -> dict[str, Path]:
    """Dotted name -> file of every module of the five packages, compiled extensions included (by
    their C source: ``from sim.fem import _local_stress`` names a module, not the package)."""
    modules = {}
    for package in ORDER:
        for path in (ROOT / package).rglob("*"):
            if path.suffix not in (".py", ".c") or ".venv" in path.parts:
                continue
            parts = path.relative_to(ROOT).with_suffix("").parts
            modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return modules


def _runtime_imports(tree: ast.AST):
    """Every import statement that runs (at module level or inside a function), those under
    ``if TYPE_CHECKING:`` aside (annotations only)."""
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.If)
            and getattr(node.test, "id", getattr(node.test, "attr", "")) == "TYPE_CHECKING"
        ):
            node.body = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import | ast.ImportFrom):
            yield node


def import_graph() -> dict[str, set[str]]:
    """Module -> the first-party modules it imports anywhere (inside functions too)."""
    modules = first_party_modules()

    def resolve(name: str) -> str | None:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, set[str]] = {name: set() for name in modules}
    for name, path in modules.items():
        if path.suffix != ".py":
            continue
        for node in _runtime_imports(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                if node.level or not node.module or node.module.split(".")[0] not in ORDER:
                    continue
                names = [f"{node.module}.{alias.name}" for alias in node.names]
                targets = {resolve(n) for n in names if n in modules} or {resolve(node.module)}
            else:
                targets = {resolve(a.name) for a in node.names if a.name.split(".")[0] in ORDER}
            graph[name] |= {t for t in targets if t is not None and t != name}
    return graph


def import_loops(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected parts of more than one module (Tarjan, iteratively)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    loops = []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                part = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    part.append(member)
                    if member == node:
                        break
                if len(part) > 1:
                    loops.append(sorted(part))
    return loops


def test_no_import_loops_even_inside_functions():
    graph = import_graph()
    assert "sim.fem.model" in graph and "sim.fem._local_stress" in graph  # the extension is a module
    found = import_loops(graph)
    described = [" <-> ".join(loop) for loop in found]
    assert not found, f"modules that import each other (at the top or in a function): {described}"


def test_the_loop_finder_finds_a_loop_through_a_function():
    assert import_loops({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert import_loops({"a": {"b"}, "b": set()}) == []


COMMAND_LINE = ("sessions/cli/", "dashboard/cli.py")
"""The command-line modules: they load a command's modules when it runs, so ``--help`` stays quick and
``sessions.cli`` loads no web module (third-party libraries that are heavy or optional, VTK, PyAV,
OpenCV, device drivers, are deferred inside functions everywhere, with no first-party module between)."""


def test_first_party_modules_are_imported_at_the_top_outside_the_command_line():
    inside = []
    for path in python_files():
        name = path.relative_to(ROOT).as_posix()
        if name.startswith(COMMAND_LINE):
            continue
        for function in ast.walk(ast.parse(path.read_text())):
            if not isinstance(function, ast.FunctionDef | ast.AsyncFunctionDef):
                continue
            for node in _runtime_imports(function):
                module = node.module if isinstance(node, ast.ImportFrom) else node.names[0].name
                if isinstance(node, ast.ImportFrom) and node.level:
                    module = "relative"
                if (module or "").split(".")[0] in ORDER:
                    inside.append(f"{name}:{node.lineno} {module}")
    assert not inside, f"import these at the top of their modules (no loop needs them inside): {inside}"
