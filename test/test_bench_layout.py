"""bench/'s layout (docs/layout.md "bench/"): every bench command and path cited in the
README, docs/, the tests, the package and bench itself names a module or file that is there.
"""
from __future__ import annotations

from pathlib import Path
import re

ROOT = Path(__file__).resolve().parent.parent
#: A dotted bench name (``python -m bench.accuracy.run_benchmark``, ``bench.accuracy.peers.X``).
DOTTED = re.compile(r'(?<![\w/.])bench((?:\.[A-Za-z_]\w*)+)')
#: A bench file path (``bench/probes/node_latency.py``, ``bench/accuracy/tuned_peers.json``).
PATH = re.compile(r'(?<![\w/.])bench/[\w/]+\.(?:py|json)\b')
#: Retired scripts, cited by the notes that replaced them (at the commit that had them).
RETIRED = {'bench.body_heave_bits'}
#: The groups of bench/ (docs/layout.md): every script is in one of them.
GROUPS = ('accuracy', 'probes', 'studies')


def _texts():
    for pattern in ('README.md', 'docs/**/*.md', 'test/**/*.py', 'road_force_estimator/**/*.py',
                    'bench/**/*.py', 'bench/**/*.json', 'config/*.yaml', 'scripts/*'):
        for path in sorted(ROOT.glob(pattern)):
            if path.is_file() and '.venv' not in path.parts:
                yield path, path.read_text(encoding='utf-8', errors='replace')


def _module_prefix_exists(parts: list[str]) -> bool:
    """Whether ``bench.<parts>`` names a bench module or package, or a name inside one."""
    folder = ROOT / 'bench'
    for part in parts:
        if (folder / f'{part}.py').is_file():
            return True
        if not (folder / part / '__init__.py').is_file():
            return False
        folder = folder / part
    return True


def test_every_cited_bench_module_is_there():
    missing = []
    for path, text in _texts():
        for match in DOTTED.finditer(text):
            name = 'bench' + match.group(1)
            if name.rsplit('.', 1)[-1] in ('py', 'json', 'md') or name in RETIRED:
                continue
            if not _module_prefix_exists(match.group(1)[1:].split('.')):
                missing.append(f'{path.relative_to(ROOT)}: {name}')
    assert not missing, missing


def test_every_cited_bench_path_is_there():
    missing = [f'{path.relative_to(ROOT)}: {m.group(0)}' for path, text in _texts()
               for m in PATH.finditer(text) if not (ROOT / m.group(0)).is_file()]
    assert not missing, missing


def test_every_script_is_in_a_group():
    loose = [p.name for p in (ROOT / 'bench').glob('*.py')
             if p.name not in ('__init__.py', 'output_hashes.py')]
    assert not loose, f'bench scripts outside {GROUPS}: {loose}'


def test_every_study_has_its_note():
    """An investigation is kept as the command of its note (docs/notes/<name>.md), which cites
    it; a note names its script's command."""
    missing = []
    for path in sorted((ROOT / 'bench' / 'studies').glob('*.py')):
        if path.stem == '__init__':
            continue
        note = ROOT / 'docs' / 'notes' / f'{path.stem}.md'
        if not note.is_file() or f'bench.studies.{path.stem}' not in note.read_text():
            missing.append(path.stem)
    assert not missing, f'studies without a note that cites them: {missing}'
