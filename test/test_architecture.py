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
    'calibration': {'core', 'estimation'},
    'serde': {'interfaces'},
    'bagio': {'interfaces', 'core', 'estimation', 'serde'},
    'report': {'interfaces', 'core', 'estimation', 'calibration'},
    'ros': {'interfaces', 'core', 'estimation', 'serde', 'bagio'},
    'pipeline': {'interfaces', 'core', 'estimation', 'calibration', 'bagio', 'report'},
    'tools': {'interfaces', 'core', 'estimation', 'calibration', 'bagio', 'report', 'pipeline'},
}
BAG_LIBRARIES = {'rosbags', 'mcap', 'mcap_ros2'}
#: The concerns that may import the bag libraries: the codec (rosbags' typestore) and the bags.
BAG_CONCERNS = {'serde', 'bagio'}
ROS_LIBRARIES = {'rclpy', 'builtin_interfaces', 'std_msgs', 'sensor_msgs', 'geometry_msgs',
                 'diagnostic_msgs', 'rosgraph_msgs', 'rcl_interfaces', 'rosidl_runtime_py'}


class Package:
    """The modules of a package folder and the imports each makes."""

    def __init__(self, root: pathlib.Path, *known: pathlib.Path):
        """The modules under ``root``; those of the ``known`` package folders are known too
        (their private names are found), but are not this package's."""
        self.root = root
        self.name = root.name
        self.own = {self._module_name(p, root): p for p in sorted(root.rglob('*.py'))}
        self.modules = dict(self.own)
        for other in known:
            self.modules.update({self._module_name(p, other): p for p in other.rglob('*.py')})

    @staticmethod
    def _module_name(path: pathlib.Path, root: pathlib.Path) -> str:
        parts = path.relative_to(root.parent).with_suffix('').parts
        return '.'.join(parts[:-1] if parts[-1] == '__init__' else parts)

    def _resolve(self, module: str, node: ast.ImportFrom) -> str:
        """The absolute name of a ``from ... import`` source (relative imports resolved)."""
        if not node.level:
            return node.module or ''
        is_package = self.modules[module].name == '__init__.py'
        parts = module.split('.')
        base = parts[: len(parts) - node.level + is_package]
        return '.'.join(base + ([node.module] if node.module else []))

    def tree(self, module: str) -> ast.Module:
        return ast.parse(self.modules[module].read_text(), filename=str(self.modules[module]))

    def imports(self, module: str) -> list[tuple[str, list[str], int]]:
        """``(imported module, names taken from it, line)`` for every import in ``module``."""
        found = []
        for node in ast.walk(self.tree(module)):
            if isinstance(node, ast.Import):
                found += [(alias.name, [], node.lineno) for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                source = self._resolve(module, node)
                names = [alias.name for alias in node.names]
                # ``from pkg.sub import mod`` imports the module pkg.sub.mod
                subs = [n for n in names if f'{source}.{n}' in self.modules]
                found += [(f'{source}.{n}', [], node.lineno) for n in subs]
                rest = [n for n in names if n not in subs]
                if rest or not subs:  # only modules taken: no dependency on the package
                    found.append((source, rest, node.lineno))
        return found

    def internal(self, name: str) -> str | None:
        """The package module that ``name`` refers to (its longest known prefix), or None."""
        parts = name.split('.')
        for end in range(len(parts), 0, -1):
            candidate = '.'.join(parts[:end])
            if candidate in self.modules:
                return candidate
        return None

    def concern(self, module: str) -> str:
        parts = module.split('.')
        return parts[1] if len(parts) > 1 else ''

    def graph(self) -> dict[str, set[str]]:
        """Module -> the package modules it imports (a package's ``__init__`` re-exports
        only, so the package root itself is no edge)."""
        graph = {}
        for module in self.modules:
            targets = {self.internal(name) for name, _, _ in self.imports(module)}
            graph[module] = {t for t in targets if t and t not in (module, self.name)}
        return graph

    def cycle(self) -> list[str] | None:
        """One import cycle, or None."""
        graph, state, stack = self.graph(), {}, []

        def visit(node: str) -> list[str] | None:
            state[node] = 1
            stack.append(node)
            for target in sorted(graph[node]):
                if state.get(target) == 1:
                    return stack[stack.index(target):] + [target]
                if target not in state and (found := visit(target)):
                    return found
            stack.pop()
            state[node] = 2
            return None

        for module in sorted(graph):
            if module not in state and (found := visit(module)):
                return found
        return None

    def layering_errors(self, module: str) -> list[str]:
        """Imports of ``module`` that go the wrong way or reach a library it may not."""
        concern = self.concern(module)
        if not concern:
            return []
        allowed = ALLOWED.get(concern, set()) | {concern, ''}
        bad = []
        for name, _, line in self.imports(module):
            target, root = self.internal(name), name.split('.')[0]
            if target and target != self.name and self.concern(target) not in allowed:
                bad.append(f'line {line}: {name} ({self.concern(target)}/ is not below '
                           f'{concern}/)')
            if root in BAG_LIBRARIES and concern not in BAG_CONCERNS:
                bad.append(f'line {line}: {name} (only serde/ and bagio/ use the bag '
                           'libraries)')
            if root in ROS_LIBRARIES and concern != 'ros':
                bad.append(f'line {line}: {name} (only ros/ imports the ROS client libraries)')
        return bad

    def private_uses(self, module: str) -> list[str]:
        """Private (``_name``) names of other package modules that ``module`` uses."""
        bad, aliases = [], {}
        for name, names, line in self.imports(module):
            target = self.internal(name)
            if target and target != module:
                bad += [f'line {line}: {n} from {target}' for n in names
                        if n.startswith('_') and not n.startswith('__')]
        tree = self.tree(module)
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                source = self._resolve(module, node)
                aliases.update({a.asname or a.name: f'{source}.{a.name}' for a in node.names
                                if f'{source}.{a.name}' in self.modules})
            elif isinstance(node, ast.Import):
                aliases.update({a.asname: a.name for a in node.names
                                if a.name in self.modules and a.asname})
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                    and node.value.id in aliases and node.attr.startswith('_')
                    and not node.attr.startswith('__')):
                bad.append(f'line {node.lineno}: {node.value.id}.{node.attr}')
        return bad


PKG = Package(ROOT)
#: The benchmarks and investigations (bench/): not the package, but held to its private-name
#: rule, across their own modules and the package's.
BENCH = Package(ROOT.parent / 'bench', ROOT)


def test_every_subpackage_has_a_rule():
    concerns = {PKG.concern(m) for m in PKG.modules} - {''}
    assert concerns <= set(ALLOWED), f'subpackages without a rule: {concerns - set(ALLOWED)}'


def test_no_import_cycles():
    cycle = PKG.cycle()
    assert cycle is None, 'import cycle: ' + ' -> '.join(cycle)


@pytest.mark.parametrize('module', sorted(PKG.modules))
def test_imports_go_one_way(module):
    bad = PKG.layering_errors(module)
    assert not bad, f'{module}: ' + '; '.join(bad)


@pytest.mark.parametrize('module', sorted(PKG.modules))
def test_no_private_names_of_other_modules(module):
    bad = PKG.private_uses(module)
    assert not bad, f'{module} uses private names of other modules: ' + '; '.join(bad)


@pytest.mark.parametrize('module', sorted(BENCH.own))
def test_bench_uses_no_private_names(module):
    """bench/ (issue 27: its scripts took each other's private names) keeps the rule too."""
    bad = BENCH.private_uses(module)
    assert not bad, f'{module} uses private names of other modules: ' + '; '.join(bad)


#: The filter code of the model observer: it takes a vehicle model (estimation/models/
#: protocol.py) and may import no vehicle's own module, nor the front axle's rows.
FILTER_PACKAGES = ('road_force_estimator.estimation.observer',
                   'road_force_estimator.estimation.smoothing')
VEHICLE_MODULES = ('road_force_estimator.estimation.models.front_axle',
                   'road_force_estimator.estimation.models.front_axle_rows',
                   'road_force_estimator.estimation.reconstruction',
                   'road_force_estimator.estimation.static_load')


@pytest.mark.parametrize('module', sorted(m for m in PKG.modules if m.startswith(FILTER_PACKAGES)))
def test_the_filter_code_never_knows_the_vehicle(module):
    """No module of observer/ or smoothing/ imports a vehicle model's module (issue 27: a
    second vehicle is a second model module, not a second observer)."""
    bad = [f'line {line}: {name}' for name, _, line in PKG.imports(module)
           if (PKG.internal(name) or '').startswith(VEHICLE_MODULES)]
    assert not bad, f'{module} imports a vehicle: ' + '; '.join(bad)


def test_the_checks_see_each_kind_of_violation(tmp_path):
    """A made-up package with one violation of each rule: every rule finds its own."""
    root = tmp_path / 'pkg'
    files = {
        '__init__.py': '',
        'core/__init__.py': '',
        'core/a.py': 'def f():\n    from pkg.estimation import b\n',     # lazy, upward
        'estimation/__init__.py': '',
        'estimation/b.py': 'from ..core import a\nfrom pkg.core.a import _hidden\n'
                           'import rosbags\n',
        'ros/__init__.py': '',
        'ros/c.py': 'import rclpy\nfrom pkg.core import a as mod\nx = mod._secret\n',
    }
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    pkg = Package(root)
    assert pkg.cycle() in (['pkg.core.a', 'pkg.estimation.b', 'pkg.core.a'],
                           ['pkg.estimation.b', 'pkg.core.a', 'pkg.estimation.b'])
    assert any('estimation/ is not below core/' in e for e in pkg.layering_errors('pkg.core.a'))
    assert any('only serde/ and bagio/' in e for e in pkg.layering_errors('pkg.estimation.b'))
    assert pkg.layering_errors('pkg.ros.c') == []
    assert pkg.private_uses('pkg.estimation.b') == ['line 2: _hidden from pkg.core.a']
    assert pkg.private_uses('pkg.ros.c') == ['line 3: mod._secret']


#: The pipeline's plan: the one module that decides whether a drive goes in blocks.
PLAN_MODULE = 'road_force_estimator.pipeline.plan'
#: What that decision reads: the threshold and the metadata's counts it is made from.
PLAN_NAMES = {'STREAM_MIN_SAMPLES', 'ONE_BLOCK_BYTES_PER_SAMPLE', 'stream_threshold',
              'plan_drive', 'streamable', 'listed_messages'}
#: The modules that define those names (bagio: the counts) or use them inside the pipeline.
PLAN_USERS = ('road_force_estimator.pipeline.', 'road_force_estimator.bagio.drive_blocks')


def plan_uses(pkg: Package, module: str) -> list[str]:
    """Where ``module`` reads the block plan or its inputs (names of :data:`PLAN_NAMES`, or an
    import of the plan or of the many-block stages), outside the pipeline."""
    if module == PLAN_MODULE or module.startswith(PLAN_USERS):
        return []
    bad = []
    for name, names, line in pkg.imports(module):
        target = pkg.internal(name) or ''
        if target.endswith(('pipeline.plan', 'pipeline.blocks')):
            bad.append(f'line {line}: imports {target}')
        bad += [f'line {line}: {n} from {target}' for n in names if n in PLAN_NAMES]
    for node in ast.walk(pkg.tree(module)):
        if isinstance(node, ast.Attribute) and node.attr in PLAN_NAMES:
            bad.append(f'line {node.lineno}: .{node.attr}')
        elif isinstance(node, ast.Name) and node.id in PLAN_NAMES:
            bad.append(f'line {node.lineno}: {node.id}')
    return bad


@pytest.mark.parametrize('module', sorted(PKG.modules))
def test_only_the_pipeline_decides_whether_to_stream(module):
    """No module outside pipeline/ decides whether a drive goes in blocks (issue 27): only
    pipeline/plan.py reads the threshold, nothing outside the pipeline imports the plan or
    the many-block stages or counts a bag's messages to choose."""
    bad = plan_uses(PKG, module)
    assert not bad, f'{module} decides whether to stream: ' + '; '.join(bad)


def test_the_plan_rule_sees_a_decision_outside_the_pipeline(tmp_path):
    root = tmp_path / 'road_force_estimator'
    files = {'__init__.py': '', 'pipeline/__init__.py': '',
             'pipeline/plan.py': 'STREAM_MIN_SAMPLES = 1\n',
             'tools/__init__.py': '',
             'tools/a.py': 'from road_force_estimator.pipeline import plan\n'
                           'big = plan.STREAM_MIN_SAMPLES\n',
             'tools/b.py': 'def f(p):\n    from road_force_estimator.bagio.drive_blocks '
                           'import streamable\n    return streamable(p) > 5\n'}
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    pkg = Package(root)
    assert any('pipeline.plan' in e for e in plan_uses(pkg, 'road_force_estimator.tools.a'))
    assert any('STREAM_MIN_SAMPLES' in e for e in plan_uses(pkg, 'road_force_estimator.tools.a'))
    assert any('streamable' in e for e in plan_uses(pkg, 'road_force_estimator.tools.b'))
    assert plan_uses(pkg, 'road_force_estimator.pipeline.plan') == []
