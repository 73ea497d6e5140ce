"""What the offline commands write: never half-written, never someone else's, never the input.

Each command builds its output in a temporary folder beside it (same file system: ``.<name>.tmp-*``
beside a bag folder or a CSV file, ``DIR/.estimate_bag.tmp-*`` inside estimate_bag's DIR) and
renames it into place only when complete. A failure (out of space, an OS error, a bad input
found late) removes the temporary folder and leaves what was there before; the error names
the cause ("out of space" for ENOSPC or EDQUOT, else the OS reason).

``--force`` replaces only what the command itself wrote, and never its input:

- a bag folder (``simulate_bag``, ``profile_to_bag``): its ``metadata.yaml`` ``custom_data``
  names the writer, and it holds nothing but ``metadata.yaml`` and the files that lists;
- ``estimate_bag``'s ``DIR/bag`` and ``DIR/report``: every file in them is listed in
  ``DIR/``:data:`MARKER_NAME`, which estimate_bag writes with them;
- a CSV file (``profile_to_bag``): it begins with the header the command writes.

Anything else is refused with :class:`OutputError`, naming what would have been replaced.

A run that is killed (SIGKILL, a power cut) cannot remove its temporary folder: each holds a
lock (``.lock``, ``flock``) while its run lives, and the next run that stages beside it
removes every temporary folder of the same name whose lock no process holds (one without a
lock, as a run killed at its very start leaves, once it is a minute old). SIGINT and SIGTERM
remove it at once (:func:`.cli.run_main` raises SIGTERM as an exception).
"""
from __future__ import annotations

from contextlib import contextmanager
import errno
import fcntl
import json
import os
from pathlib import Path
import shutil
import tempfile
import time
from typing import Callable, Iterator, Sequence
import uuid

__all__ = ['MARKER_NAME', 'STAGE_LOCK', 'OutputError', 'os_reason', 'write_error',
           'is_within', 'check_not_input', 'bag_metadata', 'remove_stale_stages',
           'staged_path', 'BagOutput', 'FolderOutput', 'FileOutput']

#: estimate_bag's marker in DIR: the files it wrote (JSON ``{"writer", "files"}``).
MARKER_NAME = '.written-by-road-force-estimator.json'
#: errno values reported as "out of space".
SPACE_ERRNOS = (errno.ENOSPC, errno.EDQUOT)
#: Largest metadata.yaml or marker read to decide ownership (bytes).
_MAX_METADATA_BYTES = 1 << 20
#: The lock file inside a temporary folder, held (``flock``) while its run lives.
STAGE_LOCK = '.lock'
#: Age (s) from which a temporary folder without a lock is taken as left by a killed run.
_UNLOCKED_STALE_S = 60.0


class OutputError(ValueError):
    """An output that cannot be written or may not be replaced (exit status 1)."""


def os_reason(err: BaseException) -> str | None:
    """The OS reason behind ``err`` (it, its cause or its context): ``'out of space (...)'``
    for ENOSPC / EDQUOT, else the OS message; None when no OSError is behind it."""
    seen: set[int] = set()
    e: BaseException | None = err
    while e is not None and id(e) not in seen:
        seen.add(id(e))
        if isinstance(e, OSError) and e.errno is not None:
            text = e.strerror or os.strerror(e.errno)
            return f'out of space ({text})' if e.errno in SPACE_ERRNOS else text
        e = e.__cause__ or e.__context__
    return None


def write_error(target: Path, err: BaseException) -> BaseException:
    """``err`` as an :class:`OutputError` naming ``target`` and the OS reason; ``err`` itself
    when no OSError is behind it (a bad input found while writing keeps its message)."""
    if isinstance(err, OutputError):
        return err
    reason = os_reason(err)
    if reason is None:
        return err
    return OutputError(f'cannot write {target}: {reason}; nothing was written')


def is_within(path: str | Path, folder: str | Path) -> bool:
    """True when ``path`` is ``folder`` or inside it (both resolved)."""
    try:
        Path(path).resolve().relative_to(Path(folder).resolve())
        return True
    except (ValueError, OSError):
        return False


def check_not_input(targets: Sequence[Path], inputs: Sequence[str | Path], prog: str) -> None:
    """Raise :class:`OutputError` when an input is one of ``targets`` or inside one."""
    for target in targets:
        for given in inputs:
            if given is not None and is_within(given, target):
                raise OutputError(f'{target} holds the input {given}: {prog} never replaces '
                                  'its input; choose another --output')


def bag_metadata(path: Path) -> tuple[dict[str, str], list[str]] | None:
    """``(custom_data, relative_file_paths)`` of a bag folder's metadata.yaml, None when it
    has none or one of the wrong shape."""
    import yaml

    meta = path / 'metadata.yaml'
    try:
        if not meta.is_file() or meta.stat().st_size > _MAX_METADATA_BYTES:
            return None
        doc = yaml.safe_load(meta.read_text('utf-8'))
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return None
    info = doc.get('rosbag2_bagfile_information') if isinstance(doc, dict) else None
    if not isinstance(info, dict):
        return None
    custom = info.get('custom_data') or {}
    files = info.get('relative_file_paths') or []
    if not isinstance(custom, dict) or not isinstance(files, list):
        return None
    return {str(k): str(v) for k, v in custom.items()}, [str(f) for f in files]


def _exists(path: Path) -> bool:
    return path.exists() or path.is_symlink()


def _refuse_existing(path: Path, force: bool) -> bool:
    """False when ``path`` is free; True when it exists and ``force``; raise otherwise."""
    if not _exists(path):
        return False
    if not force:
        raise OutputError(f'{path} exists (use --force to replace it)')
    return True


def _install(moves: Sequence[tuple[Path, Path]], stage: Path) -> None:
    """Rename every ``src`` to its ``dst``, what was at ``dst`` first moved into ``stage``;
    all or nothing (an error renames back what was moved)."""
    undo: list[tuple[Path, Path]] = []
    try:
        for i, (src, dst) in enumerate(moves):
            if _exists(dst):
                keep = stage / f'.old-{i}'
                os.rename(dst, keep)
                undo.append((keep, dst))
            os.rename(src, dst)
            undo.append((dst, src))
    except OSError:
        for a, b in reversed(undo):
            try:
                os.rename(a, b)
            except OSError:
                pass
        raise


def _stale(stage: Path, now: float) -> bool:
    """Whether the temporary folder ``stage`` was left by a run that is gone: its lock is
    free, or it has none and is older than :data:`_UNLOCKED_STALE_S`."""
    lock = stage / STAGE_LOCK
    try:
        fd = os.open(lock, os.O_RDONLY | os.O_NOFOLLOW)
    except FileNotFoundError:
        try:
            return now - stage.lstat().st_mtime > _UNLOCKED_STALE_S
        except OSError:
            return False
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return True
    except OSError:
        return False
    finally:
        os.close(fd)


def remove_stale_stages(parent: Path, prefix: str) -> list[Path]:
    """Remove the temporary folders ``parent/<prefix>*`` that killed runs left (see the
    module notes); the ones removed."""
    removed = []
    now = time.time()
    try:
        entries = [p for p in parent.iterdir() if p.name.startswith(prefix)]
    except OSError:
        return removed
    for stage in entries:
        if stage.is_symlink() or not stage.is_dir() or not _stale(stage, now):
            continue
        shutil.rmtree(stage, ignore_errors=True)
        removed.append(stage)
    return removed


def _lock_stage(stage: Path) -> int:
    """Create and hold ``stage/``:data:`STAGE_LOCK`; its file descriptor."""
    fd = os.open(stage / STAGE_LOCK, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    return fd


@contextmanager
def _staging(target: Path, parent: Path, prefix: str, made: list[Path]) -> Iterator[Path]:
    """A temporary folder in ``parent`` (created with its missing parents, which go again
    on failure when empty), locked while it lives and removed at the end (with the ones
    killed runs left there); errors as :func:`write_error` of ``target``."""
    stage = None
    fd = None
    try:
        missing = [p for p in [parent, *parent.parents] if not _exists(p)]
        parent.mkdir(parents=True, exist_ok=True)
        made.extend(missing)
        remove_stale_stages(parent, prefix)
        stage = Path(tempfile.mkdtemp(prefix=prefix, dir=parent))
        fd = _lock_stage(stage)
        yield stage
    except BaseException as err:
        if stage is not None:
            shutil.rmtree(stage, ignore_errors=True)
            stage = None
        for p in made:                               # the innermost first
            try:
                p.rmdir()
            except OSError:
                break
        new = write_error(target, err)
        if new is err:
            raise
        raise new from None
    finally:
        if stage is not None:
            shutil.rmtree(stage, ignore_errors=True)
        if fd is not None:
            os.close(fd)


@contextmanager
def staged_path(path: str | Path) -> Iterator[Path]:
    """A temporary path (in a temporary folder beside ``path``) renamed onto ``path`` when the
    block ends without error, replacing the file or folder there; on an error, or a signal,
    nothing changes at ``path``. No ownership check: the caller decides what may be
    replaced."""
    path = Path(path)
    with _staging(path, path.parent, f'.{path.name}.tmp-', []) as stage:
        yield stage / path.name
        if _exists(stage / path.name):
            _install([(stage / path.name, path)], stage)


class _OneOutput:
    """One path a command writes (a bag folder or a file): ``owned`` says whether an existing
    one is the command's own; the inputs are never replaced."""

    def __init__(self, path: str | Path, prog: str, *, force: bool, owned: Callable,
                 inputs: Sequence = ()) -> None:
        self.path, self.prog, self.force = Path(path), prog, force
        self.owned, self.inputs = owned, list(inputs)

    def _exists(self) -> bool:
        """Refuse an input as the output; True when an existing output must be vetted
        (``--force`` given), False when there is nothing there."""
        check_not_input([self.path], self.inputs, self.prog)
        return _refuse_existing(self.path, self.force)

    def _not_ours(self) -> OutputError:
        return OutputError(f'{self.path} was not written by {self.prog}: --force replaces '
                           f'only what {self.prog} wrote; not replacing it')


class BagOutput(_OneOutput):
    """A bag folder a command writes (``simulate_bag``, ``profile_to_bag``).

    Parameters
    ----------
    path : Path
        The bag folder.
    prog : str
        The command (named in the messages).
    force : bool
        Replace an existing bag folder the command wrote.
    owned : callable
        ``owned(custom_data) -> bool``: the bag's ``custom_data`` says the command wrote it.
    inputs : sequence of paths
        What the command reads (never replaced).
    """

    def check(self) -> None:
        """Raise :class:`OutputError` unless the bag may be written (or replaced)."""
        path = self.path
        if not self._exists():
            return
        if path.is_symlink() or not path.is_dir():
            raise OutputError(f'{path} exists and is not a folder: not replacing it')
        found = bag_metadata(path)
        if found is None or not self.owned(found[0]):
            raise self._not_ours()
        allowed = {'metadata.yaml', *found[1]}
        extra = sorted(p.name for p in path.iterdir()
                       if p.name not in allowed or p.is_symlink() or not p.is_file())
        if extra:
            raise OutputError(f'{path} holds {", ".join(extra[:3])}, which {self.prog} did '
                              'not write: not replacing it')

    @contextmanager
    def staged(self) -> Iterator[Path]:
        """The path to write the bag to (same name, in a temporary folder beside it); renamed
        into place when the block ends without error."""
        self.check()
        with _staging(self.path, self.path.parent, f'.{self.path.name}.tmp-', []) as stage:
            yield stage / self.path.name
            self.check()
            _install([(stage / self.path.name, self.path)], stage)


class FileOutput(_OneOutput):
    """A file a command writes (``profile_to_bag``'s CSV); ``owned(path) -> bool`` says an
    existing file is one the command wrote."""

    def check(self) -> None:
        """Raise :class:`OutputError` unless the file may be written (or replaced)."""
        path = self.path
        if not self._exists():
            return
        if path.is_symlink() or not path.is_file():
            raise OutputError(f'{path} exists and is not a file: not replacing it')
        if not self.owned(path):
            raise self._not_ours()

    @contextmanager
    def staged(self) -> Iterator[Path]:
        """A temporary path beside the file; renamed onto it when the block ends without
        error (the file keeps the usual permissions: it is created by the writer)."""
        self.check()
        with _staging(self.path, self.path.parent, f'.{self.path.name}.tmp-', []) as stage:
            tmp = stage / f'{self.path.name}.{uuid.uuid4().hex[:8]}'
            yield tmp
            self.check()
            os.replace(tmp, self.path)


class FolderOutput:
    """The named entries (``bag``, ``report``) a command writes into a folder DIR, listed file
    by file in ``DIR/``:data:`MARKER_NAME` (``estimate_bag``); other files in DIR are never
    touched."""

    def __init__(self, folder: str | Path, names: Sequence[str], prog: str, *, force: bool,
                 inputs: Sequence = ()) -> None:
        self.folder, self.names, self.prog = Path(folder), tuple(names), prog
        self.force, self.inputs = force, list(inputs)

    def _listed(self) -> set[str] | None:
        """The files the marker lists (relative paths), None without a marker of ``prog``."""
        marker = self.folder / MARKER_NAME
        try:
            if marker.is_symlink() or marker.stat().st_size > _MAX_METADATA_BYTES:
                return None
            doc = json.loads(marker.read_text('utf-8'))
        except (OSError, UnicodeDecodeError, ValueError):
            return None
        if not isinstance(doc, dict) or doc.get('writer') != self.prog \
                or not isinstance(doc.get('files'), list):
            return None
        files = doc['files']
        return {str(f) for f in files}

    def _files(self, root: Path) -> list[str]:
        """Every file (or link) under ``root``, relative to DIR."""
        if root.is_symlink() or not root.is_dir():
            return [root.relative_to(root.parent).as_posix()]
        found = []
        for here, dirs, files in os.walk(root):
            rel = Path(here).relative_to(self.folder)
            found += [(rel / f).as_posix() for f in files]
            found += [(rel / d).as_posix() for d in dirs if Path(here, d).is_symlink()]
        return sorted(found)

    def check(self) -> None:
        """Raise :class:`OutputError` unless the entries may be written (or replaced)."""
        folder = self.folder
        if _exists(folder) and not folder.is_dir():
            raise OutputError(f'{folder} exists and is not a folder')
        targets = [folder / n for n in self.names]
        check_not_input(targets + [folder / MARKER_NAME], self.inputs, self.prog)
        present = [t for t in targets if _exists(t)]
        if not present or not _refuse_existing(present[0], self.force):
            return
        listed = self._listed()
        for target in present:
            if listed is None:
                raise OutputError(f'{target} was not written by {self.prog} (no '
                                  f'{MARKER_NAME} of it in {folder}): --force replaces only '
                                  f'what {self.prog} wrote; not replacing it')
            extra = [f for f in self._files(target) if f not in listed]
            if extra:
                raise OutputError(f'{folder / extra[0]} was not written by {self.prog}: not '
                                  f'replacing {target}')

    @contextmanager
    def staged(self) -> Iterator[Path]:
        """A temporary folder in DIR to write the entries into; they and the marker are
        renamed into DIR when the block ends without error."""
        self.check()
        made: list[Path] = []
        with _staging(self.folder, self.folder, f'.{self.prog}.tmp-', made) as stage:
            yield stage
            self.check()
            names = [n for n in self.names if _exists(stage / n)]
            files = sorted(p.relative_to(stage).as_posix() for n in names
                           for p in [stage / n, *(stage / n).rglob('*')]
                           if p.is_file() or p.is_symlink())
            (stage / MARKER_NAME).write_text(json.dumps(
                {'writer': self.prog, 'files': files}, indent=1) + '\n', 'utf-8')
            _install([(stage / n, self.folder / n) for n in names]
                     + [(stage / MARKER_NAME, self.folder / MARKER_NAME)], stage)
            made.clear()                              # DIR is kept from now on

