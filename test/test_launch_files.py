"""launch/*.launch.xml (issue 17): the `launch` package is not on PyPI, so the files are parsed
here: every executable, package, parameter and parameter file they name exists."""
import ast
import importlib
import pathlib
import re
import xml.etree.ElementTree as ET

import pytest

REPO = pathlib.Path(__file__).resolve().parents[1]
PACKAGE = ET.parse(REPO / 'package.xml').getroot().findtext('name')
LAUNCH_FILES = sorted((REPO / 'launch').glob('*.launch.xml'))


def executables() -> dict[str, str]:
    """setup.py's EXECUTABLES (name -> subpackage), read from its source."""
    tree = ast.parse((REPO / 'setup.py').read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and getattr(node.targets[0], 'id', '') == 'EXECUTABLES':
            return ast.literal_eval(node.value)
    raise AssertionError('setup.py has no EXECUTABLES')


def resolve(text: str, args: dict[str, str]) -> str:
    """$(var NAME) and $(find-pkg-share PACKAGE) as launch substitutes them (the package's
    share folder is laid out as the checkout: config/, launch/)."""
    text = re.sub(r'\$\(var (\w+)\)', lambda m: args[m.group(1)], text)
    text = text.replace(f'$(find-pkg-share {PACKAGE})', str(REPO))
    assert '$(' not in text, f'unresolved substitution in {text!r}'
    return text


def test_both_launch_files_exist_and_are_installed():
    assert [p.name for p in LAUNCH_FILES] == ['replay.launch.xml', 'simulation.launch.xml']
    assert "('share/' + PACKAGE + '/launch', glob('launch/*.launch.xml'))" in (
        REPO / 'setup.py').read_text()


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_every_node_parameter_and_file_named_exists(path):
    root = ET.parse(path).getroot()
    assert root.tag == 'launch'
    args = {a.get('name'): a.get('default') for a in root.findall('arg')}
    assert all(v is not None for v in args.values()), args
    nodes = root.findall('node')
    assert nodes
    exes = executables()
    for node in nodes:
        exe = node.get('exec')
        assert node.get('pkg') == PACKAGE
        assert exe in exes and exes[exe] == 'ros', exe
        specs = {s.name for s in importlib.import_module(f'{PACKAGE}.ros.{exe}').SPECS}
        for param in node.findall('param'):
            if param.get('from') is not None:
                file = pathlib.Path(resolve(param.get('from'), args))
                assert file.is_file(), file
                assert file.suffix == '.yaml'
            else:
                assert param.get('name') in specs, (exe, param.get('name'))
                resolve(param.get('value'), args)


def test_simulation_and_replay_start_the_nodes_the_readme_says():
    names = {p.name: [n.get('exec') for n in ET.parse(p).getroot().findall('node')]
             for p in LAUNCH_FILES}
    assert sorted(names['simulation.launch.xml']) == ['bag_recorder', 'observer',
                                                      'plant_simulator']
    assert sorted(names['replay.launch.xml']) == ['bag_recorder', 'observer']
