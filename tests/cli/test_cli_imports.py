"""The CLI's boundaries (docs/architecture.md, "Layers"): a command module uses no other command module's insides
(what two commands share lives in the application layer, rpf_fly/app/), and nothing in the package below the CLI
imports it (only the entry point, ``python -m rpf_fly``). Read from the source with :mod:`ast`, nothing imported."""

from __future__ import annotations

import ast
from pathlib import Path

import rpf_fly

PACKAGE = Path(rpf_fly.__file__).resolve().parent
CLI = PACKAGE / "cli"
ENTRY_POINTS = {PACKAGE / "__main__.py"}
"""``python -m rpf_fly``: the one module outside the CLI that starts it (pyproject's ``rpf-fly`` script names
``rpf_fly.cli:main`` itself)."""


def private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def cli_module_of(node: ast.ImportFrom, path: Path) -> str | None:
    """The CLI module an ``import from`` reads (``rpf_fly.cli``, ``rpf_fly.cli.fly_cmd``), None when another."""
    if node.level:  # relative: from its package, rpf_fly.cli
        base = ["rpf_fly", "cli"][: max(0, 2 - (node.level - 1))]
        module = ".".join(base + ([node.module] if node.module else []))
    else:
        module = node.module or ""
    return module if module == "rpf_fly.cli" or module.startswith("rpf_fly.cli.") else None


def private_cross_imports(path: Path) -> list[str]:
    """``FILE:LINE: name`` for each private name that ``path`` takes from another CLI module: imported by name, or
    read as an attribute of a CLI module it imported (``fly_cmd._summary``)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    own = "rpf_fly.cli" if path.name == "__init__.py" else f"rpf_fly.cli.{path.stem}"
    modules: set[str] = set()  # local names bound to a CLI module
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            module = cli_module_of(node, path)
            if module is None or module == own:
                continue
            for alias in node.names:
                if private(alias.name):
                    found.append(f"{path.name}:{node.lineno}: {module}.{alias.name}")
                elif module == "rpf_fly.cli" and (CLI / f"{alias.name}.py").is_file():
                    modules.add(alias.asname or alias.name)
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("rpf_fly.cli.") and alias.asname:
                    modules.add(alias.asname)
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and private(node.attr):
            value = node.value
            if isinstance(value, ast.Name) and value.id in modules:
                found.append(f"{path.name}:{node.lineno}: {value.id}.{node.attr}")
            elif (
                isinstance(value, ast.Attribute)
                and ast.unparse(value).startswith("rpf_fly.cli.")
                and ast.unparse(value) != own
            ):
                found.append(f"{path.name}:{node.lineno}: {ast.unparse(node)}")
    return found


def imports_of(path: Path) -> list[tuple[int, str]]:
    """Every module ``path`` imports, absolute, with its line."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    package = ".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts[:-1])
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - (node.level - 1)])
                module = f"{base}.{node.module}" if node.module else base
            else:
                module = node.module or ""
            found.append((node.lineno, module))
            found += [(node.lineno, f"{module}.{alias.name}") for alias in node.names]
    return found


def test_no_cli_module_imports_another_cli_modules_private_names():
    found = [hit for path in sorted(CLI.glob("*.py")) for hit in private_cross_imports(path)]
    assert found == [], (
        "shared by two commands: move it to rpf_fly/app/ (or make it a public name of cli/output.py, "
        "cli/errors.py):\n" + "\n".join(found)
    )


def test_the_check_sees_a_private_cross_import(tmp_path):
    """The check itself: each way a command could reach into another is found, its own names and dunders are not."""
    module = CLI / "probe_cmd.py"  # never written: parsed from tmp_path under this name
    source = tmp_path / module.name
    source.write_text(
        "from rpf_fly.cli.fly_cmd import _summary, fly\n"
        "from rpf_fly.cli import fly_cmd, app, _root\n"
        "from . import worker_cmd\n"
        "import rpf_fly.cli.lab_cmd\n"
        "from rpf_fly.cli.probe_cmd import _mine\n"
        "from rpf_fly.cli import __doc__\n"
        "fly_cmd._print_event(None)\n"
        "worker_cmd._say(None)\n"
        "rpf_fly.cli.lab_cmd._gone\n"
        "app._private_of_typer\n"
    )
    found = [hit.split(": ", 1)[1] for hit in private_cross_imports(source)]
    assert sorted(found) == sorted(
        [
            "rpf_fly.cli.fly_cmd._summary",
            "rpf_fly.cli._root",
            "fly_cmd._print_event",
            "worker_cmd._say",
            "rpf_fly.cli.lab_cmd._gone",
        ]
    )


def test_nothing_below_the_cli_imports_it():
    found = [
        f"{path.relative_to(PACKAGE.parent)}:{line}: {module}"
        for path in sorted(PACKAGE.rglob("*.py"))
        if CLI not in path.parents and path not in ENTRY_POINTS
        for line, module in imports_of(path)
        if module == "rpf_fly.cli" or module.startswith("rpf_fly.cli.")
    ]
    assert found == [], 'the CLI is the top layer (docs/architecture.md, "Layers"):\n' + "\n".join(found)
