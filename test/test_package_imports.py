"""How the package's modules import each other: the reader apart from bank building, and no
import circle.

``speed_sign_detector.training`` (bank building) imports ``speed_sign_detector.recognition``
(the reader), never the other way: what the node and ``speed_sign_eval`` import must not
load the training code. The import graph is read from the source with :mod:`ast`, module-
and function-level imports alike (``if TYPE_CHECKING:`` ones too), so that a circle hidden
inside a function is found as well.
"""
from __future__ import annotations

import ast
import json
import subprocess
import sys
from collections.abc import Mapping
from pathlib import Path

import pytest

PROJECT_ROOT = Path(__file__).resolve().parents[1]
PACKAGE_NAME = 'speed_sign_detector'
PACKAGE_DIR = PROJECT_ROOT / PACKAGE_NAME
TRAINING_PACKAGE = f'{PACKAGE_NAME}.training'
#: What the node runs (both node variants, their entry point, the pipeline) and what the
#: evaluation tool imports, each of its subcommands included.
READER_SIDE_MODULES = (
    f'{PACKAGE_NAME}.ros.node', f'{PACKAGE_NAME}.ros.lifecycle_node',
    f'{PACKAGE_NAME}.ros.entry_point', f'{PACKAGE_NAME}.pipeline',
    f'{PACKAGE_NAME}.tools.eval', f'{PACKAGE_NAME}.tools.eval_crops',
    f'{PACKAGE_NAME}.tools.eval_scenes', f'{PACKAGE_NAME}.tools.eval_bag')
#: The only module outside the training package allowed to import it: the bank-building
#: command line (``speed_sign_train``).
TRAINING_CLIENTS = (f'{PACKAGE_NAME}.tools.train',)


def package_modules(package_dir: Path, package_name: str) -> dict[str, Path]:
    """Dotted module name -> source file of every module of the package (a package's
    ``__init__.py`` under the package's own name)."""
    modules: dict[str, Path] = {}
    for path in sorted(package_dir.rglob('*.py')):
        parts = (package_name, *path.relative_to(package_dir).with_suffix('').parts)
        if parts[-1] == '__init__':
            parts = parts[:-1]
        modules['.'.join(parts)] = path
    return modules


def imported_modules(module: str, path: Path, known: Mapping[str, Path]) -> set[str]:
    """The modules of ``known`` that ``module`` (source ``path``) imports anywhere in its
    body (module level, functions, ``if TYPE_CHECKING:``). ``from package import name``
    counts as an import of ``package.name`` where that is a module, else of ``package``;
    relative imports are resolved against ``module``."""
    is_package = path.name == '__init__.py'
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split('.') if is_package else module.split('.')[:-1]
                base = base[:len(base) - (node.level - 1)]
                source = '.'.join([*base, *([node.module] if node.module else [])])
            else:
                source = node.module or ''
            for alias in node.names:
                submodule = f'{source}.{alias.name}'
                found.add(submodule if submodule in known else source)
    return {name for name in found if name in known and name != module}


def import_graph(package_dir: Path, package_name: str) -> dict[str, set[str]]:
    """Module -> the package's modules it imports, for every module of the package."""
    modules = package_modules(package_dir, package_name)
    return {name: imported_modules(name, path, modules) for name, path in modules.items()}


def import_cycles(graph: Mapping[str, set[str]]) -> list[list[str]]:
    """The circles of ``graph``: its strongly connected components of more than one module,
    or of one module that imports itself (Tarjan's algorithm, iterative), each sorted, in
    sorted order."""
    index_of: dict[str, int] = {}
    lowest: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []
    for root in sorted(graph):
        if root in index_of:
            continue
        work = [(root, iter(sorted(graph.get(root, ()))))]
        index_of[root] = lowest[root] = len(index_of)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, successors = work[-1]
            advanced = False
            for successor in successors:
                if successor not in index_of:
                    index_of[successor] = lowest[successor] = len(index_of)
                    stack.append(successor)
                    on_stack.add(successor)
                    work.append((successor, iter(sorted(graph.get(successor, ())))))
                    advanced = True
                    break
                if successor in on_stack:
                    lowest[node] = min(lowest[node], index_of[successor])
            if advanced:
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                lowest[parent] = min(lowest[parent], lowest[node])
            if lowest[node] == index_of[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1 or node in graph.get(node, ()):
                    components.append(sorted(component))
    return sorted(components)


def loaded_package_modules(modules: tuple[str, ...]) -> list[str]:
    """The package's modules in ``sys.modules`` of a fresh interpreter after importing
    ``modules``."""
    probe = ('import importlib, json, sys\n'
             f'for name in {list(modules)!r}:\n'
             '    importlib.import_module(name)\n'
             'print(json.dumps(sorted(m for m in sys.modules\n'
             f'                        if m.startswith({PACKAGE_NAME!r}))))')
    completed = subprocess.run([sys.executable, '-c', probe], cwd=PROJECT_ROOT,
                               capture_output=True, text=True, timeout=300, check=False)
    assert completed.returncode == 0, completed.stderr
    return json.loads(completed.stdout.strip().splitlines()[-1])


def test_cycle_finder_finds_circles_of_a_small_graph() -> None:
    graph = {'a': {'b'}, 'b': {'c'}, 'c': {'a', 'd'}, 'd': set(), 'e': {'e'},
             'f': {'g', 'd'}, 'g': {'f'}, 'h': {'a'}}
    assert import_cycles(graph) == [['a', 'b', 'c'], ['e'], ['f', 'g']]
    assert import_cycles({'a': {'b'}, 'b': {'c'}, 'c': set(), 'd': {'a', 'c'}}) == []


def test_import_graph_sees_function_level_relative_and_type_checking_imports(
        tmp_path: Path) -> None:
    package = tmp_path / 'pkg'
    (package / 'sub').mkdir(parents=True)
    (package / '__init__.py').write_text('')
    (package / 'sub' / '__init__.py').write_text('from . import inner\n')
    (package / 'sub' / 'inner.py').write_text(
        'def late():\n    from pkg.top import value\n    return value\n')
    (package / 'top.py').write_text(
        'from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n'
        '    from .sub.inner import late\nvalue = 1\n')
    (package / 'other.py').write_text('import pkg.top\nfrom pkg import sub\n')
    graph = import_graph(package, 'pkg')
    assert graph == {'pkg': set(), 'pkg.sub': {'pkg.sub.inner'},
                     'pkg.sub.inner': {'pkg.top'}, 'pkg.top': {'pkg.sub.inner'},
                     'pkg.other': {'pkg.top', 'pkg.sub'}}
    assert import_cycles(graph) == [['pkg.sub.inner', 'pkg.top']]


def test_the_package_has_no_import_circle() -> None:
    graph = import_graph(PACKAGE_DIR, PACKAGE_NAME)
    assert f'{PACKAGE_NAME}.recognition.classifier' in graph, 'package not found'
    assert import_cycles(graph) == []


def test_only_the_train_command_imports_the_training_package() -> None:
    graph = import_graph(PACKAGE_DIR, PACKAGE_NAME)
    assert any(name.startswith(f'{TRAINING_PACKAGE}.') for name in graph), \
        'training package not found'
    importers = sorted(
        f'{name} imports {target}' for name, targets in graph.items()
        if not (name == TRAINING_PACKAGE or name.startswith(f'{TRAINING_PACKAGE}.'))
        and name not in TRAINING_CLIENTS
        for target in targets
        if target == TRAINING_PACKAGE or target.startswith(f'{TRAINING_PACKAGE}.'))
    assert importers == []


@pytest.mark.parametrize('modules', [READER_SIDE_MODULES], ids=['node-pipeline-eval'])
def test_node_and_eval_imports_do_not_load_the_training_code(
        modules: tuple[str, ...]) -> None:
    loaded = loaded_package_modules(modules)
    assert f'{PACKAGE_NAME}.recognition.classifier' in loaded  # the reader is loaded
    assert [name for name in loaded if name.startswith(TRAINING_PACKAGE)] == []


def test_training_probe_sees_the_train_command_load_the_training_code() -> None:
    """The probe of the test above can fail: the train command does load training."""
    loaded = loaded_package_modules(TRAINING_CLIENTS)
    assert f'{TRAINING_PACKAGE}.bank_training' in loaded
