"""Writing outputs safely: atomic files, whole output folders, and never deleting what fusion-vo did not write.

Every file and folder fusion-vo writes goes through this module, so every output follows the user's umask
(a file is created with mode ``0o666`` and a folder with ``0o777``, both reduced by the umask, exactly as
``open()`` and ``mkdir`` do).

:func:`write_atomic`
    One file, written to a hidden temporary file in the same folder and renamed into place: a reader sees
    the old file or the new one, never half of it.
:class:`StagedFiles`
    New files added to an existing folder (``fusion-vo evaluate`` adding its metrics, figures and report
    to a run folder): written into a hidden staging folder inside it and renamed into place only when all
    of them were written. The renames are journalled (:data:`COMMIT_JOURNAL`): if the process is killed
    among them, the next command writing the folder finishes them first, so the folder never keeps a mix
    of two commands' files.
:class:`OutputFolder`
    A whole output folder (a run, a generated or imported recording). Everything is written into a hidden
    staging folder beside the target; :meth:`OutputFolder.commit` swaps it into place in one rename and only
    then removes the previous folder. If anything fails, or the process is interrupted, the staging folder
    is removed and the target is left as it was. A process killed between the two renames of the swap
    (the previous folder moved aside, the new one not yet in place) leaves both in the hidden folder; the
    next command writing that target moves the new one, complete, into place. While it is open the target
    is locked, so two commands writing the same folder at once fail cleanly instead of mixing their files.

A single picture (``fusion-vo show-matches -o FILE.png``) carries the PNG text ``Software: fusion-vo``
(:data:`PNG_SOFTWARE`, written by every plot); :func:`check_picture_target` lets a command replace only a
picture that carries it.

The folder rules (the reason of this module): an existing target is replaced only if it is empty or holds
the marker file that fusion-vo writes into every output folder of that kind (``marker``); any other folder
needs ``force=True``. Even with ``force``, the current folder, a folder above it, a folder that holds one
of the command's inputs, and an existing folder inside an input that fusion-vo did not write are never
replaced.
"""

from __future__ import annotations

import errno
import fcntl
import json
import logging
import os
import secrets
import shutil
import signal
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterable, Iterator

from fusion_vo.errors import InputError

log = logging.getLogger(__name__)

#: prefix of the hidden staging folders (removed when a command ends, whatever happens)
STAGING_PREFIX = ".fusion-vo-staging-"


class Terminated(BaseException):
    """Raised in the main thread when the process receives SIGTERM or SIGHUP (see :func:`handle_signals`)."""

    def __init__(self, signum: int):
        self.signum = signum
        super().__init__(f"terminated by signal {signal.Signals(signum).name}")


@contextmanager
def handle_signals() -> Iterator[None]:
    """Turn SIGTERM and SIGHUP into :class:`Terminated` while the block runs, so ``finally`` clauses clean up.

    SIGINT already raises ``KeyboardInterrupt``. Outside the main thread this does nothing.
    """
    def raise_terminated(signum, frame):
        raise Terminated(signum)

    previous = {}
    try:
        for name in ("SIGTERM", "SIGHUP"):
            sig = getattr(signal, name, None)
            if sig is not None:
                previous[sig] = signal.signal(sig, raise_terminated)
    except ValueError:  # not the main thread
        pass
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _random_name(prefix: str) -> str:
    return f"{prefix}{secrets.token_hex(4)}"


def check_folder_target(path: str | Path, what: str = "output folder") -> Path:
    """Raise :class:`InputError` if the folder ``path`` cannot be created because it, or a folder above it,
    is a file (checked before a command's work, and by :func:`make_folder`)."""
    path = Path(path)
    for p in (path, *path.parents):
        if os.path.lexists(p):
            if not p.is_dir():
                where = "a file of that name exists" if p == path else f"{p} is a file"
                raise InputError(f"the {what} must be a folder, but {where}", path)
            break
    return path


def make_folder(path: str | Path, what: str = "output folder") -> Path:
    """Create a folder and its parents (mode ``0o777`` less the umask); an existing folder is fine, a file
    in the way is an :class:`InputError`."""
    path = check_folder_target(path, what)
    path.mkdir(parents=True, exist_ok=True)
    return path


def write_atomic(path: str | Path, data: bytes | str) -> Path:
    """Write ``data`` to ``path`` through a temporary file in the same folder and a rename.

    The file's mode is ``0o666`` less the umask, like any file ``open(path, "w")`` creates; replacing an
    existing file does not change that rule.
    """
    path = Path(path)
    payload = data.encode("utf-8") if isinstance(data, str) else data
    parent = path.parent
    for _ in range(100):
        tmp = parent / _random_name(f".{path.name}.tmp-")
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
            break
        except FileExistsError:
            continue
        except OSError as exc:  # name the file being written, not the temporary name
            raise OSError(exc.errno, exc.strerror, str(path)) from None
    else:  # pragma: no cover - 100 collisions of 32 random bits
        raise FileExistsError(errno.EEXIST, "cannot create a temporary file", str(parent))
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(payload)
        os.replace(tmp, path)
    except BaseException as exc:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        if isinstance(exc, OSError):  # a full disk, a quota: name the file being written
            raise OSError(exc.errno, exc.strerror, str(path)) from None
        raise
    return path


#: the PNG ``Software`` text of every picture fusion-vo writes (how one it wrote is told from the user's own)
PNG_SOFTWARE = "fusion-vo"


def png_software(path: str | Path) -> str | None:
    """The ``Software`` text of a PNG file's ``tEXt`` chunks, or ``None`` (no such text, not a PNG, unreadable)."""
    try:
        with open(path, "rb") as fh:
            data = fh.read(1 << 20)  # the text chunks of a picture written by matplotlib come first
    except OSError:
        return None
    if not data.startswith(b"\x89PNG\r\n\x1a\n"):
        return None
    pos = 8
    while pos + 8 <= len(data):
        length, kind = int.from_bytes(data[pos:pos + 4], "big"), data[pos + 4:pos + 8]
        body = data[pos + 8:pos + 8 + length]
        if kind == b"tEXt" and b"\0" in body:
            key, text = body.split(b"\0", 1)
            if key == b"Software":
                return text.decode("latin-1")
        if kind in (b"IDAT", b"IEND"):
            return None
        pos += 12 + length
    return None


def check_picture_target(path: str | Path, what: str = "output image") -> None:
    """Raise :class:`InputError` when ``path`` exists and is not a picture fusion-vo wrote (a file without
    the PNG text ``Software: fusion-vo``, a folder, a link): it is never overwritten."""
    path = Path(path)
    if os.path.lexists(path) and (path.is_symlink() or not path.is_file() or png_software(path) != PNG_SOFTWARE):
        raise InputError(f"the {what} exists and fusion-vo did not write it; give another file name (or remove "
                         "it first)", path)


def _inside(path: Path, folder: Path) -> bool:
    """Whether ``path`` is ``folder`` or lies under it (both resolved)."""
    try:
        path.relative_to(folder)
        return True
    except ValueError:
        return False


def check_outside(target: str | Path, inputs: Iterable[str | Path], what: str = "output folder") -> None:
    """Raise :class:`InputError` if ``target`` (a file or folder to write) is one of ``inputs`` or lies inside
    one (a recording): outputs go beside the inputs, never into them."""
    resolved = Path(target).resolve()
    for p in inputs:
        if _inside(resolved, Path(p).resolve()):
            raise InputError(f"the {what} is part of an input of this command ({p}); give another {what}", target)


def check_replaceable(target: str | Path, marker: str, force: bool = False,
                      inputs: Iterable[str | Path] = (), what: str = "output folder",
                      remedy: str = "give a new folder, or --force to replace it") -> None:
    """Raise :class:`InputError` unless ``target`` may be written (and an existing one replaced).

    Parameters
    ----------
    target : the folder to write.
    marker : name of the marker file fusion-vo leaves in folders of this kind.
    force : allow replacing a non-empty folder without the marker.
    inputs : paths the command reads; the target may not be or contain any of them.
    what : words for the folder in messages.
    remedy : what the message tells the user to do about a folder fusion-vo did not write (a command
        without ``--force`` says so).
    """
    target = Path(target)
    resolved = target.resolve()
    if resolved == Path(resolved.anchor):
        raise InputError(f"refusing to use the root folder as the {what}", target)
    cwd = Path.cwd().resolve()
    if _inside(cwd, resolved):
        raise InputError(f"refusing to replace the current folder or a folder above it; give a new {what}", target)
    for p in inputs:
        if _inside(Path(p).resolve(), resolved):
            raise InputError(f"the {what} holds an input of this command ({p}); give another {what}", target)
    if os.path.lexists(target) and not target.is_dir():
        raise InputError(f"the {what} must be a folder, but a file of that name exists", target)
    if target.is_dir() and not (target / marker).is_file():
        for p in inputs:
            if _inside(resolved, Path(p).resolve()) and any(target.iterdir()):
                raise InputError(f"the {what} is part of an input of this command ({p}); give another "
                                 f"{what}", target)
    if target.is_dir() and not (target / marker).is_file() and not force:
        try:
            empty = not any(target.iterdir())
        except OSError as exc:
            raise InputError(f"cannot read the {what} ({exc.strerror})", target) from None
        if not empty:
            raise InputError(f"the {what} exists, is not empty and was not written by fusion-vo; {remedy}", target)


class _LockedStaging:
    """What :class:`OutputFolder` and :class:`StagedFiles` share: the folder's lock, a hidden staging folder
    made under it, its removal when the block is left, and errors that name final paths, never the staging one.

    A subclass sets ``_final`` (the path errors should name) and calls :meth:`_stage`.
    """

    path: Path | None = None  # where the new files are written
    _final: Path
    _holder: Path | None = None  # the hidden folder removed on leaving
    _lock_fd: int | None = None
    _lock_path: Path | None = None

    def _stage(self, lock_target: Path, what: str, under_lock: Callable[[], None], holder_parent: Path,
               inner: str | None) -> None:
        """Lock ``lock_target``, run ``under_lock`` (checks and stale-staging removal), then make the hidden
        folder ``holder_parent/.fusion-vo-staging-...`` and, when ``inner`` is given, a folder of that name
        inside it: ``self.path``. Anything raised releases what was taken."""
        self._lock_fd, self._lock_path = lock_folder(lock_target, what)
        try:
            under_lock()
            holder = holder_parent / _random_name(STAGING_PREFIX)
            try:
                os.mkdir(holder, 0o777)
            except OSError as exc:  # permissions, a read-only file system: name the folder being written
                raise OSError(exc.errno, exc.strerror, str(self._final)) from None
            self._holder = holder
            self.path = self._holder if inner is None else self._holder / inner
            if inner is not None:
                os.mkdir(self.path, 0o777)
        except BaseException:
            self._cleanup()
            raise

    def __exit__(self, exc_type, exc, tb) -> None:
        self._cleanup()
        if self.path is not None:
            _name_final_paths(exc, self.path, self._final)
        return None

    def _cleanup(self) -> None:
        if self._holder is not None:
            shutil.rmtree(self._holder, ignore_errors=True)
            self._holder = None
        if self._lock_fd is not None:
            unlock_folder(self._lock_fd, self._lock_path)
            self._lock_fd = None


class OutputFolder(_LockedStaging):
    """Write a whole folder under a staging name and move it into place when complete.

    Use as a context manager::

        with OutputFolder(out, marker=".fusion-vo-run") as staging:
            ...write into staging (a folder named like ``out``)...
            staging_folder.commit()

    Leaving the block without :meth:`commit` (an error, an interrupt) removes the staging folder and
    leaves ``out`` untouched. :class:`InputError` raised inside the block that name a path in the staging
    folder are re-raised with the final path, so messages never show the staging name.

    Parameters
    ----------
    target : the folder to write.
    marker : marker file written into the folder (its presence later allows replacing it).
    force : replace a non-empty folder without the marker.
    inputs : paths the command reads (never replaced, never inside the target).
    what : words for the folder in messages.
    marker_text : content of the marker file.
    """

    def __init__(self, target: str | Path, marker: str, force: bool = False, inputs: Iterable[str | Path] = (),
                 what: str = "output folder", marker_text: str = "written by fusion-vo\n"):
        self.target = Path(target)
        if self.target.name in ("", ".", ".."):  # name the folder itself, not a relative step
            self.target = Path(os.path.abspath(self.target))
        self.marker = marker
        self.force = force
        self.inputs = list(inputs)
        self.what = what
        self.marker_text = marker_text
        self._final = self.target
        self.committed = False

    # ------------------------------------------------------------------ context
    def __enter__(self) -> "OutputFolder":
        check_replaceable(self.target, self.marker, self.force, self.inputs, self.what)
        make_folder(self.target.parent)

        def under_lock() -> None:
            check_replaceable(self.target, self.marker, self.force, self.inputs, self.what)  # again, under the lock
            self._remove_stale_staging()

        self._stage(self.target, self.what, under_lock, self.target.parent, self.target.name)
        return self

    def public(self, path: str | Path) -> Path:
        """The final path of a path inside the staging folder (other paths are returned unchanged)."""
        return _final_path(path, self.path, self.target)

    # ------------------------------------------------------------------ commit
    def commit(self) -> Path:
        """Write the marker and move the staging folder into place, replacing the previous folder."""
        assert self.path is not None, "commit() outside the with block"
        write_atomic(self.path / self.marker, self.marker_text)
        old = None
        if self.target.is_dir():
            old = self._holder / _random_name(".previous-")
            os.rename(self.target, old)
        try:
            os.rename(self.path, self.target)
        except BaseException:
            if old is not None:
                os.rename(old, self.target)
            raise
        self.committed = True
        return self.target

    # ------------------------------------------------------------------ internals
    def _remove_stale_staging(self) -> None:
        """Remove staging folders of this target left by a process that was killed (SIGKILL, power loss).

        Only folders that look exactly like ours are removed: named ``STAGING_PREFIX...`` beside the target and
        holding nothing but a folder of the target's name or a previous version. Any writer of this target
        would hold the lock we now hold, so such a folder belongs to no running command.
        """
        parent = self.target.parent
        try:
            candidates = [p for p in parent.iterdir() if p.name.startswith(STAGING_PREFIX) and p.is_dir()
                          and not p.is_symlink()]
        except OSError:
            return
        for holder in candidates:
            try:
                names = [c.name for c in holder.iterdir()]
            except OSError:
                continue
            if names and all(n == self.target.name or n.startswith(".previous-") for n in names):
                staged = holder / self.target.name
                if not os.path.lexists(self.target) and (staged / self.marker).is_file():
                    # killed between the two renames of commit(): the previous folder was moved aside and
                    # the new one, complete (its marker is written last), not yet moved in. Finish the swap.
                    os.rename(staged, self.target)
                    log.warning("%s: completed the replacement of the folder that an interrupted command had "
                                "written", self.target)
                log.info("removing %s, left by an interrupted command", holder)
                shutil.rmtree(holder, ignore_errors=True)


def _final_path(path: str | Path, staging: Path | None, final: Path) -> Path:
    """``path`` with the staging folder ``staging`` replaced by ``final`` (other paths unchanged)."""
    path = Path(path)
    if staging is not None and _inside(path, staging):
        return final / path.relative_to(staging)
    return path


def _name_final_paths(exc: BaseException | None, staging: Path, final: Path) -> None:
    """Errors name the final paths, never the staging folder: an :class:`InputError` naming it is raised
    again with the final path; an ``OSError``'s file name is corrected in place."""
    if isinstance(exc, InputError):
        fixed = None if exc.path is None else _final_path(exc.path, staging, final)
        message = exc.message.replace(str(staging), str(final))
        if fixed != exc.path or message != exc.message:
            raise InputError(message, fixed, exc.line) from None
    if isinstance(exc, OSError) and exc.filename:
        exc.filename = str(_final_path(exc.filename, staging, final))


def lock_folder(target: Path, what: str = "output folder") -> tuple[int, Path]:
    """Take the exclusive lock on ``.NAME.lock`` beside ``target`` (the lock every writer of that folder
    takes); fail at once with :class:`InputError` if another command has it. Returns the descriptor and path."""
    lock_path = target.parent / f".{target.name}.lock"
    while True:
        try:
            fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o666)
        except OSError as exc:  # permissions, a read-only file system: name the folder being written
            raise OSError(exc.errno, exc.strerror, str(target)) from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise InputError(f"another fusion-vo command is writing this {what}; "
                             "wait for it to finish", target) from None
        try:  # the holder before us may have removed the lock file after we opened it: retry
            same = os.fstat(fd).st_ino == os.stat(lock_path).st_ino
        except FileNotFoundError:
            same = False
        if same:
            return fd, lock_path
        os.close(fd)


def unlock_folder(fd: int, lock_path: Path) -> None:
    """Release a lock taken by :func:`lock_folder` (and remove its file)."""
    try:
        os.unlink(lock_path)
    except FileNotFoundError:
        pass
    os.close(fd)


#: journal of a :meth:`StagedFiles.commit` in progress, in the folder being written
COMMIT_JOURNAL = ".fusion-vo-commit"


def finish_staged_commit(folder: str | Path) -> list[str]:
    """Finish the :meth:`StagedFiles.commit` whose journal is in ``folder``; the names moved (none without one).

    Call with the folder's lock held (:class:`StagedFiles` does). Every file of the journal still in its
    staging folder is moved into place, the earlier files matching its patterns that the new set does not
    hold are removed, then the journal. A journal that cannot be read is removed with a warning: the
    files it named stay as they are.
    """
    folder = Path(folder)
    path = folder / COMMIT_JOURNAL
    if not path.is_file():
        return []
    try:
        journal = json.loads(path.read_text())
        staging = folder / str(journal["staging"])
        names = [str(n) for n in journal["files"]]
        replaces = [str(p) for p in journal["replaces"]]
        if not staging.name.startswith(STAGING_PREFIX) or any("/" in n or n in ("", ".", "..") for n in names):
            raise ValueError("not a journal of fusion-vo")
    except (OSError, ValueError, KeyError, TypeError) as exc:
        log.warning("%s: cannot read it (%s); removed", path, exc)
        path.unlink(missing_ok=True)
        return []
    moved = []
    for name in names:
        if os.path.lexists(staging / name):
            os.replace(staging / name, folder / name)
            moved.append(name)
    for pattern in replaces:
        for old in folder.glob(pattern):
            if old.name not in names and old.is_file():
                old.unlink()
    path.unlink()
    return moved


class StagedFiles(_LockedStaging):
    """New files for an existing folder (an evaluation added to a run folder), all or nothing.

    Use as a context manager::

        with StagedFiles(run_dir, replaces=("metrics.json", "report.html", "*.png")) as staged:
            ...write the new files into staged.path...
            staged.commit()

    The files are written into a hidden staging folder inside ``folder``; :meth:`commit` renames each into
    place and then removes the earlier files matching ``replaces`` that the new set does not hold (a
    figure an earlier evaluation drew and this one does not). Leaving the block without :meth:`commit`
    (an error, an interrupt) removes the staging folder: the folder keeps its earlier files, untouched.
    The folder is locked meanwhile with the lock of :class:`OutputFolder`, so a run writing it at the
    same time fails cleanly. Errors raised inside that name a staged file name the final file instead.
    With ``create``, a missing folder is made (:func:`make_folder`) and, when the block is left without
    :meth:`commit`, removed again: a failed command leaves no folder it made.
    """

    def __init__(self, folder: str | Path, replaces: Iterable[str] = (), what: str = "run folder",
                 create: bool = False):
        self.folder = Path(folder)
        self.replaces = tuple(replaces)
        self.what = what
        self.create = create
        self._final = self.folder
        self._created = False
        self._committed = False

    def __enter__(self) -> "StagedFiles":
        def under_lock() -> None:
            moved = finish_staged_commit(self.folder)  # a commit a killed process had begun
            if moved:
                log.warning("%s: moved in the %d files an interrupted command had written (%s)", self.folder,
                            len(moved), ", ".join(moved))
            for stale in self.folder.glob(STAGING_PREFIX + "*"):  # left by a killed process (we hold the lock)
                if stale.is_dir() and not stale.is_symlink():
                    shutil.rmtree(stale, ignore_errors=True)

        if self.create:
            self._created = not os.path.lexists(self.folder)
            make_folder(self.folder, self.what)
        try:
            self._stage(self.folder, self.what, under_lock, self.folder, None)
        except BaseException:
            self._remove_created()
            raise
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if self._holder is not None and (self.folder / COMMIT_JOURNAL).is_file():
            finish_staged_commit(self.folder)  # interrupted inside commit(): every file was written, move them in
            self._committed = True
        super().__exit__(exc_type, exc, tb)
        if not self._committed:
            self._remove_created()
        return None

    def _remove_created(self) -> None:
        if self._created:  # only a folder this block made, and only what it wrote there
            shutil.rmtree(self.folder, ignore_errors=True)
            self._created = False

    def commit(self) -> list[Path]:
        """Move the new files into the folder; returns their final paths.

        The files are moved one by one, so first a journal (:data:`COMMIT_JOURNAL`) names the staging folder,
        the files and the patterns they replace; it is removed when all are in place. A process killed in
        between (SIGKILL, power loss) leaves the journal, and the next command that writes the folder
        finishes the moves before anything else (:func:`finish_staged_commit`).
        """
        assert self.path is not None, "commit() outside the with block"
        names = sorted(p.name for p in self.path.iterdir())
        journal = {"staging": self.path.name, "files": names, "replaces": list(self.replaces)}
        write_atomic(self.folder / COMMIT_JOURNAL, json.dumps(journal))
        finish_staged_commit(self.folder)
        self._committed = True
        return [self.folder / name for name in names]
