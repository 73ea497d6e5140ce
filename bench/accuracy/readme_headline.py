"""The README's headline table, copied from the benchmark's own page (issue 30: every figure
on the README's first screen from the benchmark's run).

``python -m bench.accuracy.run_benchmark --docs docs/benchmark.md`` writes the page; this command
then takes its headline table (section "Headline") and writes the README's block between
``<!-- headline:begin -->`` and ``<!-- headline:end -->``: the rows of the columns named in
:data:`ROWS` (ours in each latency group beside the best-tuned model-based Kalman peer), the
load and profile errors of the noisy class A and class C drives. Nothing is computed here:
the figures are the page's strings.

Run: ``.venv/bin/python -m bench.accuracy.readme_headline [--check]`` (``--check``: exit 1 if the
README's block differs from what the page gives, writing nothing).
"""
from __future__ import annotations

import argparse
from pathlib import Path
import sys

ROOT = Path(__file__).resolve().parents[2]
BEGIN, END = '<!-- headline:begin -->', '<!-- headline:end -->'
#: (benchmark column, what the README calls it)
ROWS = (
    ('kf-model', 'Kalman peer on the same model (tuned, given the true noise)'),
    ('ours-online', '**ours, zero latency** (the `observer` node, default)'),
    ('paper-euler', "the paper's explicit-Euler Levant chain"),
    ('kf-model-lag10ms', 'Kalman peer, exact 10 ms fixed lag'),
    ('ours-latency-10ms', '**ours, `observer.latency: 0.01`**'),
    ('kf-model-rts', 'Kalman peer, RTS smoother'),
    ('ours-offline', '**ours, `estimate_bag --mode offline`**'),
)
SCENARIOS = ('A20-1k-10um', 'C20-1k-10um')


def headline_rows(page: str) -> dict[str, dict[str, str]]:
    """{column: {header: cell}} of the page's headline table."""
    lines = page.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith('## Headline'))
    table = []
    for line in lines[start + 1:]:
        if line.startswith('## '):
            break
        if line.startswith('|'):
            table.append([c.strip() for c in line.strip().strip('|').split('|')])
    header, body = table[0], table[2:]
    return {row[0].strip('*'): dict(zip(header, row)) for row in body}


def block(page: str) -> str:
    """The README block (markers included)."""
    rows = headline_rows(page)
    head = ['method', 'latency'] + [f'{what}, {s}' for s in SCENARIOS
                                    for what in ('load', 'profile')]
    out = [BEGIN, '| ' + ' | '.join(head) + ' |',
           '|---|---|' + '---:|' * (len(head) - 2)]
    for column, name in ROWS:
        r = rows[column]
        cells = [name, r['latency']] + [r[f'{what}, {s}'] for s in SCENARIOS
                                        for what in ('load', 'profile')]
        out.append('| ' + ' | '.join(cells) + ' |')
    out.append(END)
    return '\n'.join(out)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--page', type=Path, default=ROOT / 'docs' / 'benchmark.md')
    p.add_argument('--readme', type=Path, default=ROOT / 'README.md')
    p.add_argument('--check', action='store_true', help='compare only; exit 1 if different')
    args = p.parse_args(argv)
    readme = args.readme.read_text(encoding='utf-8')
    if BEGIN not in readme or END not in readme:
        print(f'readme_headline: no {BEGIN} ... {END} block in {args.readme}', file=sys.stderr)
        return 2
    before, rest = readme.split(BEGIN, 1)
    old, after = rest.split(END, 1)
    new = block(args.page.read_text(encoding='utf-8'))
    if args.check:
        same = BEGIN + old + END == new
        print('README headline ' + ('matches' if same else 'differs from') + f' {args.page}')
        return 0 if same else 1
    args.readme.write_text(before + new + after, encoding='utf-8')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
