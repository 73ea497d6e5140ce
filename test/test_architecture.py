"""The package's import structure (issue 15): subpackages by concern, imports one way.

Read from the source with :mod:`ast` (every ``import`` statement, module level or inside a
function), never by importing the package, so that a forbidden import fails here even when
the module that holds it is never imported by a test.
"""
from __future__ import annotations

import ast
import pathlib

import pytest

PACKAGE = 'road_force_estimator'
ROOT = pathlib.Path(__file__).resolve().parents[1] / PACKAGE

# Which subpackages each may import (besides itself); a top-level module is its own concern.
ALLOWED = {
    'interfaces': set(),
    'core': set(),
    'estimation': {'core'},
    'bagio': {'interfaces', 'core', 'estimation'},
    'report': {'interfaces', 'core', 'estimation'},
    'ros': {'interfaces', 'core', 'estimation', 'bagio'},
    'tools': {'interfaces', 'core', 'estimation', 'bagio', 'report'},
}
BAG_LIBRARIES = {'rosbags', 'mcap', 'mcap_ros2'}
ROS_LIBRARIES = {'rclpy', 'builtin_interfaces', 'std_msgs', 'sensor_msgs', 'geometry_msgs',
                 'diagnostic_msgs', 'rosgraph_msgs', 'rcl_interfaces', 'rosidl_runtime_py'}


def _module_name(path: pathlib.Path) -> str:
    parts = path.relative_to(ROOT.parent).with_suffix('').parts
    return '.'.join(parts[:-1] if parts[-1] == '__init__' else parts)


MODULES = {_module_name(p): p for p in sorted(ROOT.rglob('*.py'))}


def _resolve(module: str, node: ast.ImportFrom) -> str:
    """The absolute name of a ``from ... import`` source (relative imports resolved)."""
    if not node.level:
        return node.module or ''
    is_package = MODULES[module].name == '__init__.py'
    base = module.split('.')[: len(module.split('.')) - node.level + is_package]
    return '.'.join(base + ([node.module] if node.module else []))


def _imports(module: str) -> list[tuple[str, list[str], int]]:
    """``(imported module, names taken from it, line)`` for every import in ``module``."""
    tree = ast.parse(MODULES[module].read_text(), filename=str(MODULES[module]))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(alias.name, [], node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            source = _resolve(module, node)
            names = [alias.name for alias in node.names]
            # ``from pkg.sub import mod`` imports the module pkg.sub.mod
            submodules = [f'{source}.{n}' for n in names if f'{source}.{n}' in MODULES]
            found += [(name, [], node.lineno) for name in submodules]
            rest = [n for n in names if f'{source}.{n}' not in MODULES]
            found.append((source, rest, node.lineno))
    return found


def _internal(name: str) -> str | None:
    """The package module that ``name`` refers to (its longest known prefix), or None."""
    parts = name.split('.')
    for end in range(len(parts), 0, -1):
        candidate = '.'.join(parts[:end])
        if candidate in MODULES:
            return candidate
    return None


def _concern(module: str) -> str:
    parts = module.split('.')
    return parts[1] if len(parts) > 1 else ''


def _graph() -> dict[str, set[str]]:
    graph = {}
    for module in MODULES:
        targets = set()
        for name, _, _ in _imports(module):
            target = _internal(name)
            # a package's own __init__ is not an edge of its modules (it only re-exports)
            if target and target != module and target != PACKAGE:
                targets.add(target)
        graph[module] = targets
    return graph


def test_every_subpackage_is_known():
    concerns = {_concern(m) for m in MODULES} - {''}
    assert concerns <= set(ALLOWED), f'subpackages without a rule: {concerns - set(ALLOWED)}'


def test_no_import_cycles():
    graph = _graph()
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for target in sorted(graph[node]):
            if state.get(target) == 1:
                return stack[stack.index(target):] + [target]
            if target not in state:
                cycle = visit(target)
                if cycle:
                    return cycle
        stack.pop()
        state[node] = 2
        return None

    for module in sorted(graph):
        if module not in state:
            cycle = visit(module)
            assert cycle is None, 'import cycle: ' + ' -> '.join(cycle)


@pytest.mark.parametrize('module', sorted(MODULES))
def test_imports_go_one_way(module):
    concern = _concern(module)
    if not concern:
        return
    allowed = ALLOWED.get(concern, set()) | {concern}
    bad = []
    for name, _, line in _imports(module):
        target = _internal(name)
        root = name.split('.')[0]
        if target and target != PACKAGE and _concern(target) not in allowed | {''}:
            bad.append(f'line {line}: {name} ({_concern(target)}/ is not below {concern}/)')
        if root in BAG_LIBRARIES and concern != 'bagio':
            bad.append(f'line {line}: {name} (only bagio/ reads or writes bags)')
        if root in ROS_LIBRARIES and concern != 'ros':
            bad.append(f'line {line}: {name} (only ros/ imports the ROS client libraries)')
    assert not bad, f'{module}: ' + '; '.join(bad)


@pytest.mark.parametrize('module', sorted(MODULES))
def test_no_private_names_of_other_modules(module):
    tree = ast.parse(MODULES[module].read_text())
    aliases = {}
    bad = []
    for name, names, line in _imports(module):
        target = _internal(name)
        if not target or target == module:
            continue
        bad += [f'line {line}: {n} from {target}' for n in names
                if n.startswith('_') and not n.startswith('__')]
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            source = _resolve(module, node)
            for alias in node.names:
                if f'{source}.{alias.name}' in MODULES:
                    aliases[alias.asname or alias.name] = f'{source}.{alias.name}'
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name in MODULES and alias.asname:
                    aliases[alias.asname] = alias.name
    for node in ast.walk(tree):
        if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                and node.value.id in aliases and node.attr.startswith('_')
                and not node.attr.startswith('__')):
            bad.append(f'line {node.lineno}: {node.value.id}.{node.attr}')
    assert not bad, f'{module} uses private names of other modules: ' + '; '.join(bad)


def test_the_checks_see_a_forbidden_import(tmp_path):
    """The resolver itself: relative, absolute and submodule imports are all seen."""
    module = f'{PACKAGE}.core.plant'
    names = {name for name, _, _ in _imports(module)}
    assert f'{PACKAGE}.core.vehicle_model' in {_internal(n) for n in names}
