"""Output files and folders.

- Atomic files (:func:`write_bytes_atomic`, :func:`write_json_atomic`, :func:`write_csv_atomic`):
  written to a temporary file in the target folder, then renamed.
- Owned folders (:class:`OutputFolder`): a run locks its output folder (:class:`FolderLock`), writes
  every output into a fresh temporary folder inside it and moves the files into place only when
  all of them are written; the files an earlier run of the tool wrote (its manifest) that the new
  run did not write are removed, files it did not write never are. A manifest is trusted only
  when it carries the identity its tool writes (:data:`MANIFEST_FORMAT_KEY`): a ``results.json``
  or ``sweep.json`` written by another program never makes a run remove a file.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import shutil
import tempfile
from contextlib import contextmanager, suppress
from pathlib import Path, PurePosixPath
from typing import Any, Iterable, Iterator

from ddcm_casadi.errors import DDCMError, InputError

#: The lock file of an output folder (the same for every tool: one run per folder at a time).
LOCK_FILE = ".ddcm-casadi.lock"
#: Prefixes of a run's temporary folders inside its output folder (new outputs, replaced ones).
STAGING_PREFIX = ".ddcm-staging-"
PREVIOUS_PREFIX = ".ddcm-previous-"
#: The key of a manifest that says which tool and format wrote it (see :class:`OutputFolder`).
MANIFEST_FORMAT_KEY = "format"


def prepare_output_dir(path: str | os.PathLike) -> Path:
    """Create ``path`` if needed and check that it is a writable folder (fails before any work)."""
    if not str(path).strip():
        raise InputError(f"the output folder must be a path, got {str(path)!r}")
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise InputError(f"output path is not a directory: {out}")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create output directory {out}: {exc.strerror or exc}") from None
    if not out.is_dir():
        raise InputError(f"output path is not a directory: {out}")
    try:
        with tempfile.NamedTemporaryFile(dir=out, prefix=".write-test-"):
            pass
    except OSError as exc:
        raise InputError(f"output directory is not writable: {out} ({exc.strerror or exc})") from None
    return out


def umask() -> int:
    """The process's file-creation mask (read without changing it for good)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> Path:
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.chmod(tmp, 0o666 & ~umask())  # mkstemp creates 0600; give the file ordinary permissions
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def write_json_atomic(path: str | os.PathLike, obj: Any) -> Path:
    """Strict JSON: NaN and infinities (a missing check, a failed residual) are written as null."""
    text = json.dumps(_strict(obj), indent=2, allow_nan=False)
    return write_bytes_atomic(path, (text + "\n").encode())


def write_csv_atomic(path: str | os.PathLike, rows: Iterable[dict]) -> Path:
    rows = list(rows)
    columns: list[str] = []
    for row in rows:
        columns.extend(k for k in row if k not in columns)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: _csv_value(v) for k, v in row.items()})
    return write_bytes_atomic(path, buf.getvalue().encode())


def _csv_value(v):
    if v is None:
        return ""
    if isinstance(v, float):
        return repr(v)
    return v


def _strict(o):
    """``o`` with numpy values as Python ones and non-finite floats as ``None``."""
    import numpy as np

    if isinstance(o, dict):
        return {k: _strict(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_strict(v) for v in o]
    if isinstance(o, np.ndarray):
        if o.dtype.kind == "f" and not np.all(np.isfinite(o)):
            obj = o.astype(object)
            obj[~np.isfinite(o)] = None
            return obj.tolist()
        return o.tolist()  # already plain and finite: no walk over its elements
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        o = o.item()
    if isinstance(o, float) and not math.isfinite(o):
        return None
    if isinstance(o, Path):
        return str(o)
    if o is None or isinstance(o, (str, int, float, bool)):
        return o
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


# ------------------------------------------------------------------------------- owned folders
class FolderLock:
    """An exclusive, non-blocking lock on an output folder: ``fcntl.flock`` on :data:`LOCK_FILE`.

    The kernel drops the lock when the process ends, however it ends (a crash or ``kill -9``
    leaves at most an unlocked file, reused by the next run). The file holds the holder's pid and
    tool for the message of a refused run; it is removed on :meth:`release`.

    Raises
    ------
    InputError
        The folder is locked by another run (the message names the folder, the tool and its pid).
    """

    def __init__(self, folder: str | os.PathLike, tool: str) -> None:
        import fcntl  # POSIX only; imported here so that the atomic writers import anywhere

        self.path = Path(folder) / LOCK_FILE
        # A holder removes the file on release: if it did so between our open and our flock, we
        # hold a lock on a removed file, so open again until the locked file is the named one.
        for _ in range(100):
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o666 & ~umask())
            except OSError as exc:
                raise InputError(f"cannot lock output folder {Path(folder)}: {exc.strerror or exc}") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = os.read(fd, 200).decode(errors="replace").split()
                os.close(fd)
                who = f"{holder[1]} (pid {holder[0]})" if len(holder) == 2 else "another run"
                raise InputError(f"output folder {Path(folder)} is in use by {who}; "
                                 "wait for it to finish or choose another folder") from None
            except OSError as exc:
                os.close(fd)
                raise InputError(f"cannot lock output folder {Path(folder)}: {exc.strerror or exc}") from None
            try:
                if os.path.samestat(os.fstat(fd), os.stat(self.path)):
                    break
            except FileNotFoundError:
                pass
            os.close(fd)
        else:  # pragma: no cover - a hundred holders in a row
            raise InputError(f"cannot lock output folder {Path(folder)}: it is locked and unlocked too often")
        self._fd: int | None = fd
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()} {tool}\n".encode())

    def release(self) -> None:
        """Remove the lock file and drop the lock (removed first: no one locks a removed file)."""
        if self._fd is None:
            return
        try:
            os.unlink(self.path)
        except OSError:
            pass
        os.close(self._fd)
        self._fd = None

    def __enter__(self) -> "FolderLock":
        return self

    def __exit__(self, *exc) -> None:
        self.release()


class OutputFolder:
    """The output folder of one run of a tool, whose own files the run replaces as a whole.

    ``OutputFolder(path, tool=..., manifest=...)`` creates the folder if needed
    (:func:`prepare_output_dir`, before any work) and locks it (:class:`FolderLock`) until
    :meth:`close` (or the end of a ``with`` block). Outputs are written inside
    ``with folder.staging() as stage:`` into ``stage``, a fresh temporary folder inside the output
    folder; when the block ends without an error, every file written there is moved into place and
    the files listed in the previous manifest that this run did not write are removed. The
    manifest is the JSON file ``manifest`` among the outputs, with a ``files`` list of the paths
    (relative, ``/``-separated) the run wrote; the caller writes it, last. With ``identity`` (the
    value of :data:`MANIFEST_FORMAT_KEY` that the tool writes into its manifest), a manifest
    without that identity, written by another program, is not trusted: no file it lists is removed.

    On an error inside the block the temporary folder is removed and the folder keeps what it held
    (the previous complete results); an ``OSError`` (a full disk, a quota, a read-only file system)
    is raised as a one-line :class:`~ddcm_casadi.errors.DDCMError`. A folder that this object
    created and that is still empty at :meth:`close` is removed: an interrupted or failed run leaves
    nothing behind.
    """

    def __init__(self, path: str | os.PathLike, *, tool: str, manifest: str, identity: str | None = None) -> None:
        created = not Path(path).exists()
        self.path = prepare_output_dir(path)
        self.tool, self.manifest, self.identity = tool, manifest, identity
        self._created, self._committed = created, False
        self._lock = FolderLock(self.path, tool)
        try:
            self._recover()
        except BaseException:
            self._lock.release()
            raise

    def __enter__(self) -> "OutputFolder":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Release the lock (and remove the folder if this run created it and wrote nothing)."""
        self._lock.release()
        if self._created and not self._committed:
            try:
                self.path.rmdir()
            except OSError:
                pass

    @contextmanager
    def staging(self) -> Iterator[Path]:
        """A fresh temporary folder for every output of the run, moved into place at the end."""
        try:
            stage = Path(tempfile.mkdtemp(dir=self.path, prefix=STAGING_PREFIX))
        except OSError as exc:
            raise self._write_error(exc) from None
        try:
            yield stage
            self._commit(stage)
        except OSError as exc:
            raise self._write_error(exc) from None
        finally:
            shutil.rmtree(stage, ignore_errors=True)

    def _write_error(self, exc: OSError) -> DDCMError:
        return DDCMError(f"cannot write the outputs to {self.path}: {exc.strerror or exc}; "
                         "the folder keeps what it held before this run")

    def previous_files(self) -> list[str]:
        """The files an earlier run of the tool wrote here (its manifest's ``files``), those that
        are still regular files (or links) inside the folder; empty without a readable manifest,
        and without one of this tool's (``identity``, when given: another program's is not trusted)."""
        try:
            doc = json.loads((self.path / self.manifest).read_text(encoding="utf-8"))
            listed = doc.get("files")
        except (OSError, ValueError, AttributeError):
            return []
        if self.identity is not None and doc.get(MANIFEST_FORMAT_KEY) != self.identity:
            return []
        if not isinstance(listed, list):
            return []
        root = os.path.realpath(self.path)
        files = []
        for rel in listed:
            if not isinstance(rel, str) or not _own_name(rel):
                continue
            path = self.path / rel
            inside = os.path.commonpath([root, os.path.realpath(path.parent)]) == root
            if inside and (path.is_symlink() or path.is_file()):
                files.append(rel)
        return files

    def _commit(self, stage: Path) -> None:
        """Move the files of ``stage`` into place (the manifest last) and remove the previous run's
        files that this run did not write; on any failure restore the folder as it was."""
        new = sorted((p.relative_to(stage).as_posix() for p in stage.rglob("*") if p.is_file()),
                     key=lambda rel: rel == self.manifest)
        replaced = sorted(set(self.previous_files()) | {rel for rel in new if (self.path / rel).is_file()})
        previous = Path(tempfile.mkdtemp(dir=self.path, prefix=PREVIOUS_PREFIX))
        saved, placed = [], []
        try:
            for rel in replaced:  # out of the way first: kept until every new file is in place
                (previous / rel).parent.mkdir(parents=True, exist_ok=True)
                os.replace(self.path / rel, previous / rel)
                saved.append(rel)
            for rel in new:
                (self.path / rel).parent.mkdir(parents=True, exist_ok=True)
                os.replace(stage / rel, self.path / rel)
                placed.append(rel)
        except BaseException:
            for rel in placed:
                with suppress(OSError):
                    os.unlink(self.path / rel)
            _move_back(previous, self.path, saved)  # if this fails too, the next run puts them back
            raise
        self._committed = True
        # The commit point: renamed to a staging name, the previous files are no longer put back.
        done = previous.with_name(STAGING_PREFIX + previous.name[len(PREVIOUS_PREFIX):])
        try:
            os.replace(previous, done)
        except OSError:
            done = previous
        shutil.rmtree(done, ignore_errors=True)
        for rel in set(replaced) - set(new):  # folders (e.g. vtu/) that only held removed files
            for parent in PurePosixPath(rel).parents:
                if parent.name:
                    try:
                        (self.path / parent).rmdir()
                    except OSError:
                        break

    def _recover(self) -> None:
        """Clean up after a run that was killed while writing (the lock is held): its new outputs
        are dropped and the files it had moved away are put back."""
        for p in list(self.path.iterdir()):
            if p.is_dir() and not p.is_symlink() and p.name.startswith(PREVIOUS_PREFIX):
                _move_back(p, self.path, [q.relative_to(p).as_posix() for q in p.rglob("*") if q.is_file()])
            if p.is_dir() and not p.is_symlink() and p.name.startswith(STAGING_PREFIX):
                shutil.rmtree(p, ignore_errors=True)


def _own_name(rel: str) -> bool:
    """Is ``rel`` a path that a run may have written: relative, without ``..``, not hidden?"""
    parts = PurePosixPath(rel).parts
    return bool(parts) and not PurePosixPath(rel).is_absolute() and all(
        part not in ("", ".", "..") and not part.startswith(".") for part in parts)


def _move_back(saved_dir: Path, folder: Path, files: list[str]) -> None:
    """Move ``files`` from ``saved_dir`` back into ``folder``; remove ``saved_dir`` if all went back."""
    for rel in files:
        (folder / rel).parent.mkdir(parents=True, exist_ok=True)
        os.replace(saved_dir / rel, folder / rel)
    shutil.rmtree(saved_dir, ignore_errors=True)
