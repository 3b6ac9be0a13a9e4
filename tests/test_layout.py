"""The package layout's rules (docs/architecture.md), read from the sources with ``ast``.

Imports point one way (measure -> fitting -> jsss), no two modules import each other,
fitting uses only public names of jsss.render, the physics writes no file and holds no
console command, and render methods and passes are spelt only in their enumeration.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("jsss", "fitting", "measure")
LAYER = {"jsss": 0, "fitting": 1, "measure": 2}


def _modules():
    """{dotted module name: (path, is_package)} of the three packages."""
    found = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            is_package = parts[-1] == "__init__"
            if is_package:
                parts = parts[:-1]
            found[".".join(parts)] = (path, is_package)
    return found


MODULES = _modules()


def _imports(name):
    """(imported module, imported names) for every import in module ``name``, at any depth
    (a function-level import is still a dependency), relative imports resolved."""
    path, is_package = MODULES[name]
    tree = ast.parse(path.read_text(), filename=str(path))
    here = name.split(".") if is_package else name.split(".")[:-1]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, ()
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = here[: len(here) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            names = tuple(alias.name for alias in node.names)
            yield module, names
            for alias in names:  # `from pkg import module` imports that module
                if f"{module}.{alias}" in MODULES:
                    yield f"{module}.{alias}", ()


def _graph():
    edges = {}
    for name in MODULES:
        targets = set()
        for module, _ in _imports(name):
            if module.split(".")[0] in PACKAGES and module in MODULES and module != name:
                targets.add(module)
        edges[name] = targets
    return edges


def test_imports_point_one_way():
    """jsss imports neither fitting nor measure; fitting does not import measure."""
    wrong = []
    for name in MODULES:
        for module, _ in _imports(name):
            top = module.split(".")[0]
            if top in LAYER and LAYER[top] > LAYER[name.split(".")[0]]:
                wrong.append(f"{name} imports {module}")
    assert not wrong, "\n".join(wrong)


def test_no_two_modules_import_each_other():
    """A package's __init__ re-exporting its own modules is not a cycle of two modules; any
    other pair that imports each other is."""
    edges = _graph()
    pairs = []
    for a, targets in edges.items():
        for b in targets:
            if a < b and a in edges.get(b, ()):
                if MODULES[a][1] and b.startswith(a + "."):
                    continue
                if MODULES[b][1] and a.startswith(b + "."):
                    continue
                pairs.append(f"{a} <-> {b}")
    assert not pairs, "\n".join(pairs)


def test_fitting_imports_no_private_name_of_the_renderer():
    """The fit holds the solve and the statistics; the frame it fits is jsss.render's public one:
    every name fitting takes from jsss.render is in the ``__all__`` of the module it comes from."""
    import importlib

    private = []
    for name in MODULES:
        if not name.startswith("fitting"):
            continue
        for module, names in _imports(name):
            if not module.startswith("jsss.render"):
                continue
            public = getattr(importlib.import_module(module), "__all__", ())
            private += [f"{name}: {module}.{n}" for n in names
                        if n not in public and f"{module}.{n}" not in MODULES]
    assert not private, "\n".join(private)


def test_console_commands_live_in_the_command_package():
    """Every [project.scripts] entry point is a module of measure.commands."""
    import tomllib

    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts, "no console scripts declared"
    outside = {name: target for name, target in scripts.items() if not target.startswith("measure.commands.")}
    assert not outside, outside


@pytest.mark.parametrize("package", ["jsss", "fitting"])
def test_library_code_below_the_commands_holds_no_argument_parser(package):
    """argparse belongs to the commands; the physics and the fits take arguments, not argv."""
    users = [name for name in MODULES if name.startswith(package)
             and any(module == "argparse" for module, _ in _imports(name))]
    assert not users, users


def test_method_and_pass_names_are_compared_only_through_the_enumeration():
    """No ``== "texture-space"``, ``plan.on("diffusion")`` or similar outside jsss/render/passes.py
    (the packages, the benchmarks, the scripts and the notebooks)."""
    from jsss.render.passes import Method, Pass

    def alternatives(names):
        return "|".join(re.escape(n) for n in sorted(names, key=len, reverse=True))

    methods = alternatives({m.value for m in Method} | {m.option for m in Method})
    passes = alternatives({p.value for p in Pass})
    # A pass is looked up by on/replace/decisions; a method is compared. ("camera" is also a
    # white balance, so a pass name alone after == is not a method's.)
    pattern = re.compile(rf"""(\bon\(|\breplace\(|decisions\[)\s*["']({passes})["']"""
                         rf"""|(==|!=|\bin)\s*\(?["']({methods})["']""")
    assert pattern.search('if plan.on("single scattering"):') and pattern.search('method != "normal-filtering"')
    assert not pattern.search('if white_balance == "camera":')
    found = []
    sources = [path for path, _ in MODULES.values()] + sorted(
        path for folder in ("benchmarks", "scripts", "notebooks") for path in (ROOT / folder).glob("*.py"))
    for path in sources:
        if path.name == "passes.py":
            continue
        for number, line in enumerate(path.read_text().splitlines(), 1):
            if pattern.search(line):
                found.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()}")
    assert not found, "\n".join(found)


def test_the_rules_can_fail():
    """The checks above read real imports: the renderer imports the physics, and measure the fits."""
    edges = _graph()
    assert "jsss.diffusion.dipole" in set().union(*(edges[n] for n in edges if n.startswith("jsss.render")))
    assert any(t.startswith("fitting") for n in edges if n.startswith("measure") for t in edges[n])


def test_every_package_ships():
    """pyproject.toml lists its packages (examples/ ships inside jsss as jsss.examples, which a
    find would not see): every folder of the three packages with an __init__.py is listed, and
    every folder of examples/ that holds files is a listed jsss.examples package with package data,
    so `pip install .` (not editable) installs what the tree has."""
    import tomllib

    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(config["packages"])
    in_tree = {".".join(path.parent.relative_to(ROOT).parts) for package in PACKAGES
               for path in (ROOT / package).rglob("__init__.py")}
    assert in_tree <= listed, sorted(in_tree - listed)
    assert config["package-dir"] == {"jsss.examples": "examples"}
    example_folders = {".".join(("jsss", "examples") + path.relative_to(ROOT / "examples").parts)
                       for path in [ROOT / "examples", *(ROOT / "examples").rglob("*")]
                       if path.is_dir() and "__pycache__" not in path.parts}
    assert example_folders <= listed, sorted(example_folders - listed)
    assert listed <= in_tree | example_folders, sorted(listed - in_tree - example_folders)
    data = config["package-data"]
    for folder in example_folders:
        path = ROOT.joinpath("examples", *folder.split(".")[2:])
        files = {p.name for p in path.iterdir() if p.is_file() and p.suffix != ".py"}
        shipped = {name for name in files if any(Path(name).match(pattern) for pattern in data.get(folder, ()))}
        assert shipped == files, f"{folder}: {sorted(files - shipped)} would not ship"
