"""MCAP walking helpers shared by the bag tests (the MCAP specification, not bagio's code)."""
from __future__ import annotations


def top_level_records(data):
    """(opcode, offset, length) of the records outside chunks, walked from the magic."""
    pos = 8
    while pos + 9 <= len(data):
        op, length = data[pos], int.from_bytes(data[pos + 1:pos + 9], 'little')
        yield op, pos, length
        pos += 9 + length
