"""The README and docs/: links that resolve, the headline copied from the benchmark's page."""
from __future__ import annotations

from pathlib import Path
import re

from bench.accuracy import readme_headline

ROOT = Path(__file__).resolve().parent.parent
LINK = re.compile(r'\]\(([^)#\s]+)(?:#[^)]*)?\)')


def _pages() -> list[Path]:
    return [ROOT / 'README.md', *sorted((ROOT / 'docs').glob('*.md'))]


def test_every_relative_link_resolves():
    missing = []
    for page in _pages():
        for target in LINK.findall(page.read_text(encoding='utf-8')):
            if '://' in target or target.startswith('mailto:'):
                continue
            if not (page.parent / target).exists():
                missing.append(f'{page.relative_to(ROOT)} -> {target}')
    assert not missing, missing


def test_readme_headline_is_the_benchmark_pages():
    """The README's first-screen figures are the strings of docs/benchmark.md's headline table
    (written by bench.accuracy.run_benchmark), row by row."""
    readme = (ROOT / 'README.md').read_text(encoding='utf-8')
    page = (ROOT / 'docs' / 'benchmark.md').read_text(encoding='utf-8')
    start = readme.index(readme_headline.BEGIN)
    end = readme.index(readme_headline.END) + len(readme_headline.END)
    assert readme[start:end] == readme_headline.block(page)
    rows = readme_headline.headline_rows(page)
    assert rows['ours-online']['load, A20-1k-10um'] in readme[start:end]


def test_readme_is_a_front_door():
    lines = (ROOT / 'README.md').read_text(encoding='utf-8').splitlines()
    assert 150 <= len(lines) <= 200, len(lines)
    assert 'Kalman unknown-input observer' in ' '.join(lines[:8])


def test_layout_lists_every_module():
    """docs/layout.md names every module of the package (the round-2 table omitted 35)."""
    text = (ROOT / 'docs' / 'layout.md').read_text(encoding='utf-8')
    package = ROOT / 'road_force_estimator'
    missing = []
    for f in sorted(package.rglob('*.py')):
        rel = f.relative_to(package).with_suffix('')
        if rel.parts == ('__init__',):
            continue
        if f'`{".".join(rel.parts)}`' not in text:
            missing.append('.'.join(rel.parts))
    assert not missing, missing


def test_readme_quickstart_block_is_the_tested_one():
    """The README's node block is docs/quickstart.md's, which test/ros/test_quickstart_blocks.py
    runs as written."""
    pattern = re.compile(r'<!-- block: quickstart -->\s*```bash\n(.*?)```', re.S)
    readme = pattern.search((ROOT / 'README.md').read_text(encoding='utf-8'))
    page = pattern.search((ROOT / 'docs' / 'quickstart.md').read_text(encoding='utf-8'))
    assert readme and page and readme.group(1) == page.group(1)
