"""A column of numbers kept in a temporary file instead of memory (issue 21: a long drive's
per-sample columns that are needed only later, or only piece by piece).

:class:`SpillColumn` appends rows to an unnamed temporary file (:func:`tempfile.TemporaryFile`:
removed when closed or when the process ends, so a failure leaves nothing behind) and reads
them back whole (:meth:`array`) or by row range (:meth:`read`), with plain reads (no memory
map: the pages the kernel caches are not the process's memory). A full disk raises the
``OSError`` of the write (``errno.ENOSPC``). :class:`SpillRows`: a range of a file's rows
sliced as an array is (what a pass that reads a long run's rows a chunk at a time takes).
"""
from __future__ import annotations

import tempfile

import numpy as np

__all__ = ['SpillColumn', 'SpillRows']


class SpillColumn:
    """Rows of one dtype and row shape, in a temporary file (see the module notes).

    ``folder``: where the file goes (None: the system's temporary folder)."""

    def __init__(self, dtype=float, width: int | None = None, folder=None) -> None:
        self.dtype = np.dtype(dtype)
        self.shape = () if width is None else (int(width),)
        self.row_bytes = self.dtype.itemsize * (int(np.prod(self.shape)) if self.shape else 1)
        self.size = 0
        self._file = tempfile.TemporaryFile(dir=None if folder is None else str(folder))

    def append(self, rows) -> None:
        """Rows at the end (shape ``(k,) + row shape``)."""
        a = np.ascontiguousarray(rows, dtype=self.dtype)
        if a.shape[1:] != self.shape:
            raise ValueError(f'rows of shape {a.shape[1:]}, expected {self.shape}')
        self._file.seek(self.size * self.row_bytes)
        self._file.write(a.tobytes())
        self.size += a.shape[0]

    def write(self, start: int, rows) -> None:
        """Rows from row ``start`` on (written over, or past the end: rows not written
        between read as zeros)."""
        a = np.ascontiguousarray(rows, dtype=self.dtype)
        if a.shape[1:] != self.shape:
            raise ValueError(f'rows of shape {a.shape[1:]}, expected {self.shape}')
        self._file.seek(int(start) * self.row_bytes)
        self._file.write(a.tobytes())
        self.size = max(self.size, int(start) + a.shape[0])

    def read(self, start: int, stop: int) -> np.ndarray:
        """Rows ``start:stop`` (a new array)."""
        start, stop = max(0, int(start)), min(self.size, int(stop))
        k = max(0, stop - start)
        out = np.empty((k,) + self.shape, self.dtype)
        view = memoryview(out).cast('B') if k else memoryview(b'')
        self._file.seek(start * self.row_bytes)
        got = 0
        while got < len(view):
            n = self._file.readinto(view[got:])
            if not n:
                raise OSError(f'spill file: read {got} of {len(view)} bytes')
            got += n
        return out

    def array(self) -> np.ndarray:
        """Every row (a new array)."""
        return self.read(0, self.size)

    def close(self) -> None:
        self._file.close()


class SpillRows:
    """Rows ``start:stop`` of a :class:`SpillColumn` read as an array of them is indexed:
    ``rows[a:b]`` (a new array of those rows, step 1), ``rows[k]`` (one row), ``shape``,
    ``len``; :meth:`sub` a range of them. Nothing is held but the file."""

    def __init__(self, file: SpillColumn, start: int = 0, stop: int | None = None) -> None:
        self.file = file
        self.start = int(start)
        self.stop = file.size if stop is None else int(stop)
        self.dtype = file.dtype
        self.shape = (self.stop - self.start,) + file.shape
        self.ndim = len(self.shape)

    def __len__(self) -> int:
        return self.shape[0]

    def sub(self, a: int, b: int) -> 'SpillRows':
        """Rows ``a:b`` of these (0 <= a <= b <= len)."""
        return SpillRows(self.file, self.start + a, self.start + b)

    def __getitem__(self, key):
        if isinstance(key, slice):
            a, b, step = key.indices(self.shape[0])
            if step != 1:
                raise IndexError('spilled rows: slices of step 1 only')
            return self.file.read(self.start + a, self.start + max(a, b))
        k = int(key)
        if k < 0:
            k += self.shape[0]
        if not 0 <= k < self.shape[0]:
            raise IndexError(f'row {key} of {self.shape[0]}')
        return self.file.read(self.start + k, self.start + k + 1)[0]
