"""The output set of a reconstruction, written as a unit.

``reconstruct`` writes into one folder:

================  ===========================================================================
``map.json``      the map, with its provenance and every parameter (``docs/map-format.md``)
``contacts.csv``  every contact (``wholearm_tools.contact_table``)
``report_data.json``  what the report needs besides those two (``wholearm_tools.report.data``)
``map.<fmt>``     meshes (default ply, stl, obj, glb, vtp; ``wholearm_tools.mesh.export``)
``overlay.mcap``  the Foxglove overlay (``wholearm_tools.mesh.overlay``)
``report.pdf``    the PDF report, rendered from the files above (so ``wholearm report OUT/``
                  renders the same pages again)
================  ===========================================================================

**As a unit.**  Every file is first written into a hidden staging folder beside the target
(``.<name>.wholearm-<pid>-<random>``, same file system; inside the target, ``.wholearm-…``,
when the target also holds other files), and the set is put in place at the end:

* target absent: the staging folder is renamed onto it (atomic; if another process created it
  meanwhile, the rename fails and nothing is replaced);
* target holding only outputs this writer may write (a previous set): the two folders are
  swapped atomically (Linux ``renameat2(RENAME_EXCHANGE)``) and the old set is deleted;
* target holding other files too (e.g. ``-o .`` next to the log), the working directory, or on
  a system without the swap: the old ``map.json`` is removed first, then the files are moved in
  one by one with ``map.json`` last.  ``map.json`` records the sha256 of the files it was
  written with, and the readers check them, so an interrupted set is recognised rather than
  mixed.

The overwrite check runs again at the commit: two writers into one new folder never replace
each other silently.  Existing outputs must be regular files (a symbolic link, a device node or
a folder in an output's place is refused, never written through).  A set written with
``overwrite`` replaces the whole previous set: an output left out this time (``--no-report``)
does not stay behind from the earlier run.

Kill the process at any point and a folder of the first two kinds holds the old complete set or
the new complete set (plus, at worst, a hidden staging folder, removed by the next writer into
the same parent).  In a folder of the third kind a kill during the moves (milliseconds) leaves
it without map.json, which every reader refuses as incomplete; a rerun writes the whole set.
"""

from __future__ import annotations

import contextlib
import ctypes
import dataclasses
import datetime as dt
import errno
import os
import shutil
import stat
import tempfile
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from wholearm_tools import __version__, _interrupt
from wholearm_tools.errors import OutputError

MAP_NAME = "map.json"
CONTACTS_NAME = "contacts.csv"
REPORT_DATA_NAME = "report_data.json"
OVERLAY_NAME = "overlay.mcap"
REPORT_NAME = "report.pdf"
#: mesh formats ``reconstruct`` writes unless told otherwise
DEFAULT_MESH_FORMATS = ("ply", "stl", "obj", "glb", "vtp")
#: every mesh format an output set may hold
MESH_FORMATS = ("ply", "stl", "obj", "gltf", "glb", "vtp")


def reconstruction_names(extra: Iterable[str] = ()) -> frozenset[str]:
    """Every file name a reconstruction's output set may hold (plus ``extra``)."""
    return frozenset({MAP_NAME, CONTACTS_NAME, REPORT_DATA_NAME, OVERLAY_NAME, REPORT_NAME,
                      *(f"map.{fmt}" for fmt in MESH_FORMATS), *extra})


# ------------------------------------------------------------------------------ provenance


def creation_time() -> str:
    """UTC time of writing, ISO 8601 to the second; ``SOURCE_DATE_EPOCH`` (the
    reproducible-builds convention) fixes it, so outputs can be made byte-identical."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    when = (dt.datetime.fromtimestamp(int(epoch), dt.UTC) if epoch and epoch.isdigit()
            else dt.datetime.now(dt.UTC))
    return when.replace(microsecond=0).isoformat().replace("+00:00", "Z")


def relative_to_folder(path: str | os.PathLike[str], folder: str | os.PathLike[str]) -> str:
    """``path`` relative to ``folder`` (POSIX separators), so a copied or moved output folder
    still finds its inputs; absolute when there is no relative path."""
    try:
        rel = os.path.relpath(os.path.abspath(path), os.path.abspath(folder))
    except ValueError:          # another drive
        return str(Path(path).absolute())
    return Path(rel).as_posix()


def input_record(path: str | os.PathLike[str] | None, folder: str | os.PathLike[str],
                 kind: str, recorded_as: str | os.PathLike[str] | None = None
                 ) -> dict[str, Any]:
    """map.json's ``meta.input``: path relative to the map's folder, name, kind, size, sha256
    (None for an input that is not a file or folder, e.g. an in-memory run).  ``recorded_as``
    is where the input will stay when ``path`` is a staged copy (the demo's run.mcap)."""
    from wholearm_tools.report.data import sha256_of

    if path is None or not Path(path).exists():
        return {"path": None if path is None else str(path), "name": None, "kind": kind,
                "bytes": None, "sha256": None}
    p = Path(path)
    size = p.stat().st_size if p.is_file() else sum(
        c.stat().st_size for c in p.rglob("*") if c.is_file())
    where = Path(recorded_as) if recorded_as is not None else p
    return {"path": relative_to_folder(where, folder), "name": where.name, "kind": kind,
            "bytes": int(size), "sha256": sha256_of(p)}


def tool_record() -> dict[str, str]:
    return {"name": "wholearm_tools", "version": __version__}


def reconstruction_parameters(rec: Any) -> dict[str, Any]:
    """Every parameter a reconstruction depends on: B, loss and the other fit options, the
    torque source, the contact detection settings and the thresholds it derived from the log,
    and the classification settings (map.json ``meta.parameters``)."""
    from wholearm_tools.contacts import DetectionParams
    from wholearm_tools.report.data import torque_source_of

    params = {k: v for k, v in dataclasses.asdict(rec.params).items() if k != "workers"}
    settings = (getattr(rec, "detection_params", None)
                or getattr(rec.params, "detection", None) or DetectionParams())
    contacts = rec.contacts
    detection = {
        "settings": dataclasses.asdict(settings),
        "velocity_threshold": getattr(contacts, "velocity_threshold", None),
        "torque_threshold": getattr(contacts, "torque_threshold", None),
        **(getattr(contacts, "meta", None) or {}),
    }
    cls_meta = dict(getattr(rec.classification, "meta", None) or {})
    return {**params, "torque_source": torque_source_of(rec.run), "detection": detection,
            "classification": cls_meta}


def map_with_provenance(surface_map: Any, folder: str | os.PathLike[str],
                        input_path: str | os.PathLike[str] | None, kind: str,
                        parameters: dict[str, Any],
                        recorded_as: str | os.PathLike[str] | None = None) -> Any:
    """``surface_map`` with ``meta`` recording the tool, the date, the input (path relative to
    ``folder``, sha256) and the parameters; ``meta.source`` becomes the relative input path."""
    from wholearm_tools.mapfile import jsonable

    record = input_record(input_path, folder, kind, recorded_as)
    meta = dict(surface_map.meta)
    meta.update({"source": record["path"] if record["path"] is not None
                 else meta.get("source"),
                 "tool": tool_record(), "created": creation_time(), "input": record,
                 "parameters": jsonable(parameters)})
    return dataclasses.replace(surface_map, meta=meta)


# ------------------------------------------------------------------------------ the set


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths atomically (Linux ``renameat2(RENAME_EXCHANGE)``); False when the system
    or the file system cannot."""
    try:
        fn = ctypes.CDLL(None, use_errno=True).renameat2
    except (AttributeError, OSError):
        return False
    at_fdcwd, rename_exchange = -100, 2
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    if fn(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP, errno.EXDEV):
        return False
    raise OSError(code, os.strerror(code), str(b))


#: name prefix of staging folders (after ``.<target name>`` when beside the target)
STAGE_PREFIX = ".wholearm-"


def _clean_stale(where: Path, prefix: str) -> None:
    """Remove staging folders (``prefix<pid>-…`` in ``where``) left by killed writers: those
    whose process is gone."""
    with contextlib.suppress(OSError):
        for entry in where.iterdir():
            if not (entry.name.startswith(prefix) and entry.is_dir()):
                continue
            pid = entry.name[len(prefix):].split("-", 1)[0]
            if pid.isdigit() and not _pid_alive(int(pid)):
                shutil.rmtree(entry, ignore_errors=True)


def _holds_cwd(folder: Path) -> bool:
    """True when the working directory is ``folder`` or inside it."""
    try:
        cwd = os.getcwd()
    except OSError:
        return False
    return os.path.commonpath([cwd, str(folder)]) == str(folder)


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


class OutputSet:
    """A folder of outputs written as a unit (see the module docstring).

    Use as a context manager: write every file to :meth:`path` (the staging folder); on a
    normal exit the set is committed, on an exception the staging folder is removed and the
    target is left as it was::

        with OutputSet("out", reconstruction_names(), overwrite=False) as out:
            write_map(out.path("map.json"), surface_map)

    Parameters
    ----------
    folder : path
        The target folder (created with its parents if needed).
    names : iterable of str
        The file names this writer may write (and, with ``overwrite``, replace).
    overwrite : bool
        Replace an existing set; refused otherwise.
    """

    def __init__(self, folder: str | os.PathLike[str], names: Iterable[str], *,
                 overwrite: bool = False) -> None:
        self.folder = Path(folder)
        self.names = frozenset(names)
        self.overwrite = overwrite
        self.check()
        target = Path(os.path.abspath(self.folder))
        # beside the target when the whole folder may be swapped in; inside it when it also
        # holds other files, or holds the working directory (only the files move then: a
        # process working in the old folder would be left in a deleted one)
        self._keep_folder = self.folder.is_dir() and (bool(self._foreign()) or
                                                      _holds_cwd(target))
        inside = self._keep_folder
        where = target if inside else target.parent
        prefix = STAGE_PREFIX if inside else f".{target.name}{STAGE_PREFIX}"
        try:
            where.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise OutputError(f"{self.folder}: cannot create the output folder "
                              f"({exc.strerror})") from None
        _clean_stale(where, prefix)
        try:
            self.stage = Path(tempfile.mkdtemp(prefix=f"{prefix}{os.getpid()}-", dir=where))
        except OSError as exc:
            raise OutputError(f"{self.folder}: cannot write outputs ({exc.strerror})") from None
        self.committed = False

    def _foreign(self) -> list[str]:
        """Entries of the target that are neither outputs of this set nor staging folders."""
        return [e for e in os.listdir(self.folder)
                if e not in self.names and not e.startswith(STAGE_PREFIX)]

    # -------------------------------------------------------------- checks

    def _present(self) -> list[str]:
        """Names of this set already in the target, each checked to be a regular file."""
        present = []
        for name in sorted(self.names):
            target = self.folder / name
            try:
                st = os.lstat(target)
            except FileNotFoundError:
                continue
            except OSError as exc:
                raise OutputError(f"{target}: cannot check the existing output "
                                  f"({exc.strerror})") from None
            if stat.S_ISLNK(st.st_mode):
                raise OutputError(f"{target}: is a symbolic link; outputs must be regular "
                                  "files or absent (remove it first)")
            if not stat.S_ISREG(st.st_mode):
                raise OutputError(f"{target}: is not a regular file (a folder, device or "
                                  "pipe); outputs must be regular files or absent")
            present.append(name)
        return present

    def check(self) -> None:
        """Refuse a target that is not a folder, holds a non-regular file in an output's place,
        or holds outputs while ``overwrite`` is off."""
        if os.path.lexists(self.folder) and not self.folder.is_dir():
            raise OutputError(f"{self.folder}: exists and is not a folder")
        if not self.folder.exists():
            return
        present = self._present()
        if present and not self.overwrite:
            raise OutputError(f"{self.folder}: already holds {', '.join(present)} "
                              "(use --overwrite to replace)")

    # -------------------------------------------------------------- staging

    def path(self, name: str) -> Path:
        """Staging path of output ``name`` (one of ``names``)."""
        if name not in self.names:
            raise ValueError(f"{name!r} is not an output of this set ({sorted(self.names)})")
        return self.stage / name

    def final(self, name: str) -> Path:
        """Where output ``name`` will be once committed."""
        return self.folder / name

    def written(self) -> list[str]:
        """Names written to the staging folder so far (temporaries excluded)."""
        return sorted(p.name for p in self.stage.iterdir() if p.name in self.names)

    # -------------------------------------------------------------- commit

    def commit(self) -> None:
        """Put the staged set in place (see the module docstring); never once Ctrl-C was
        pressed."""
        if self.committed:
            return
        _interrupt.check()
        for entry in self.stage.iterdir():      # temporaries of a writer that failed late
            if entry.name not in self.names:
                entry.unlink() if not entry.is_dir() else shutil.rmtree(entry)
        os.chmod(self.stage, 0o777 & ~_umask())
        if not os.path.lexists(self.folder):
            try:
                os.rename(self.stage, self.folder)
            except OSError as exc:
                if exc.errno not in (errno.ENOTEMPTY, errno.EEXIST, errno.ENOTDIR):
                    raise OutputError(f"{self.folder}: cannot write outputs "
                                      f"({exc.strerror})") from None
                # created meanwhile by someone else: judge it as an existing target below
            else:
                self.committed = True
                return
        self.check()
        inside = self.stage.parent == Path(os.path.abspath(self.folder))
        if not inside and not self._foreign() and not self.folder.is_symlink() and \
                not _holds_cwd(Path(os.path.abspath(self.folder))) and self._swap():
            self.committed = True
            return
        self._move_in()
        self.committed = True

    def _swap(self) -> bool:
        """Exchange the staging folder with the target; the old set is then deleted.  Undone
        (and refused) if the target changed in between into something this set may not
        replace."""
        with contextlib.suppress(OSError):
            os.chmod(self.stage, stat.S_IMODE(os.stat(self.folder).st_mode))
        if not _exchange(self.stage, self.folder):
            return False
        old = self.stage           # after the exchange the staging path holds the old folder
        entries = [e for e in os.listdir(old) if not e.startswith(STAGE_PREFIX)]
        clash = [e for e in entries if e not in self.names]
        if clash or (not self.overwrite and entries):
            _exchange(old, self.folder)          # put the other set back
            shutil.rmtree(old, ignore_errors=True)
            raise OutputError(f"{self.folder}: was written by another process while this one "
                              "ran; left as it is (use --overwrite to replace it)")
        shutil.rmtree(old, ignore_errors=True)
        return True

    def _move_in(self) -> None:
        """Move the staged files into a target that also holds other files: the old map.json
        goes first, stale outputs of this set next, map.json comes last."""
        new = self.written()
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.folder / MAP_NAME)
        for name in self._present():
            if name not in new:
                os.unlink(self.folder / name)
        for name in sorted(new, key=lambda n: n == MAP_NAME):
            os.replace(self.stage / name, self.folder / name)
        shutil.rmtree(self.stage, ignore_errors=True)

    def discard(self) -> None:
        """Remove the staging folder (nothing is put in place)."""
        shutil.rmtree(self.stage, ignore_errors=True)

    def __enter__(self) -> OutputSet:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is None:
            try:
                self.commit()
            finally:
                if not self.committed:
                    self.discard()
        else:
            self.discard()


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


# ------------------------------------------------------------------------------ writers


def write_outputs(out: OutputSet, rec: Any, *, input_path: str | os.PathLike[str] | None = None,
                  meshes: Iterable[str] = DEFAULT_MESH_FORMATS, overlay: bool = True,
                  report: bool = True, progress: Callable[[str], None] | None = None
                  ) -> dict[str, Path]:
    """Write the output set of ``rec`` (a :class:`~wholearm_tools.pipeline.Reconstruction`)
    into the staging folder of ``out``.

    Parameters
    ----------
    out : OutputSet
        Where to write (committed by the caller, e.g. by leaving its ``with`` block).
    rec : Reconstruction
    input_path : path, optional
        The run's file as it will stay (default ``rec.run.source``); recorded relative to the
        output folder, with its sha256.
    meshes : iterable of str
        Mesh formats to write (``MESH_FORMATS``); empty for none.
    overlay, report : bool
        Write ``overlay.mcap`` / ``report.pdf``.
    progress : callable, optional
        Called with a short description before each step.

    Returns
    -------
    dict
        Final path of every output, by key (``map``, ``contacts``, ``report_data``,
        ``mesh.<fmt>``, ``overlay``, ``report``).
    """
    from wholearm_tools.contact_table import write_contact_table
    from wholearm_tools.mapfile import write_map
    from wholearm_tools.report.data import (
        dumps,
        report_data_from_reconstruction,
        report_data_to_json,
        run_info,
        sha256_of,
    )

    say = progress or (lambda _: None)
    meshes = tuple(dict.fromkeys(f.lower() for f in meshes))
    unknown = [f for f in meshes if f not in MESH_FORMATS]
    if unknown:
        raise OutputError(f"unknown mesh formats {unknown} (known: {', '.join(MESH_FORMATS)})")
    source = rec.run.source if input_path is None else input_path
    source_ok = source is not None and Path(str(source)).exists()
    staged = source_ok and Path(source).absolute().parent == out.stage.absolute()
    sm = map_with_provenance(rec.surface_map, out.folder, source if source_ok else None,
                             "log", reconstruction_parameters(rec),
                             recorded_as=out.final(Path(source).name) if staged else None)
    if not source_ok:
        sm = dataclasses.replace(sm, meta={**sm.meta, "source": str(rec.run.source)})
    paths: dict[str, Path] = {}

    say("writing the contact table")
    write_contact_table(out.path(CONTACTS_NAME), rec.table)
    paths["contacts"] = out.final(CONTACTS_NAME)

    say("replaying the tip probabilities for the report")
    record = sm.meta["input"]
    run = run_info(rec.run, source=record["path"] or str(rec.run.source),
                   sha256=record["sha256"])
    data = report_data_from_reconstruction(rec, surface_map=sm, run=run)
    doc = report_data_to_json(data, CONTACTS_NAME, sha256_of(out.path(CONTACTS_NAME)))
    out.path(REPORT_DATA_NAME).write_text(dumps(doc), encoding="utf-8")
    paths["report_data"] = out.final(REPORT_DATA_NAME)

    if meshes:
        from wholearm_tools.mesh.export import export_mesh, map_meshes, map_scene_metadata

        say("meshing and exporting " + ", ".join(meshes))
        parts = map_meshes(sm)
        if any(not p.mesh.is_empty for p in parts):
            for fmt in meshes:
                name = f"map.{fmt}"
                export_mesh(parts, out.path(name), fmt, frame=sm.frame,
                            metadata=map_scene_metadata(sm))
                paths[f"mesh.{fmt}"] = out.final(name)
    if overlay:
        from wholearm_tools.mesh.overlay import write_overlay

        say("writing the Foxglove overlay")
        write_overlay(out.path(OVERLAY_NAME), sm, rec.table, t0_ns=rec.run.log.t0_ns)
        paths["overlay"] = out.final(OVERLAY_NAME)

    hashes = {name: {"sha256": sha256_of(out.path(name))} for name in out.written()}
    sm = dataclasses.replace(sm, meta={**sm.meta, "outputs": hashes})
    write_map(out.path(MAP_NAME), sm)
    paths["map"] = out.final(MAP_NAME)

    if report:
        from wholearm_tools.report import write_report
        from wholearm_tools.report.data import load_report_data

        say("writing the PDF report")
        write_report(out.path(REPORT_NAME), load_report_data(out.path(MAP_NAME)))
        paths["report"] = out.final(REPORT_NAME)
    return paths


def write_reconstruction(out_dir: str | os.PathLike[str], rec: Any, *, overwrite: bool = False,
                         input_path: str | os.PathLike[str] | None = None,
                         meshes: Iterable[str] = DEFAULT_MESH_FORMATS, overlay: bool = True,
                         report: bool = True, progress: Callable[[str], None] | None = None
                         ) -> dict[str, Path]:
    """Write the whole output set of ``rec`` into ``out_dir`` as a unit (see the module
    docstring and :func:`write_outputs` for the parameters).  Returns the path of every output.
    """
    with OutputSet(out_dir, reconstruction_names(), overwrite=overwrite) as out:
        paths = write_outputs(out, rec, input_path=input_path, meshes=meshes, overlay=overlay,
                              report=report, progress=progress)
    return paths


def report_data_name(map_name: str) -> str:
    """Name of the report data beside a map file: ``report_data.json`` beside ``map.json``,
    ``<stem>.report_data.json`` beside any other map name."""
    return REPORT_DATA_NAME if map_name == MAP_NAME else f"{Path(map_name).stem}.report_data.json"


def write_fit(map_path: str | os.PathLike[str], table_path: str | os.PathLike[str],
              surface_map: Any, fits: Any, table: Any, messages: Iterable[str],
              parameters: dict[str, Any], *, overwrite: bool = False) -> dict[str, Path]:
    """Write a map fitted from a contact table (``wholearm fit``) and its report data beside
    it, as a unit: the report data refers to the contact table by its path relative to the
    map's folder and its sha256, and holds the fit's assignment of the contacts, so
    ``wholearm report`` renders the folder without refitting."""
    from wholearm_tools.mapfile import write_map
    from wholearm_tools.report.data import (
        ReportData,
        RunInfo,
        dumps,
        fit_infos,
        report_data_to_json,
        sha256_of,
    )

    map_path = Path(map_path)
    folder = map_path.parent if str(map_path.parent) else Path(".")
    data_name = report_data_name(map_path.name)
    with OutputSet(folder, {map_path.name, data_name}, overwrite=overwrite) as out:
        sm = map_with_provenance(surface_map, folder, table_path, "contact table", parameters)
        record = sm.meta["input"]
        data = ReportData(surface_map=sm, table=table,
                          run=RunInfo(source=record["path"], kind="contact table",
                                      sha256=record["sha256"], planar=sm.planar),
                          fits=fit_infos(sm, fits), messages=tuple(messages))
        doc = report_data_to_json(data, record["path"], record["sha256"])
        out.path(data_name).write_text(dumps(doc), encoding="utf-8")
        sm = dataclasses.replace(sm, meta={**sm.meta, "outputs": {
            data_name: {"sha256": sha256_of(out.path(data_name))}}})
        write_map(out.path(map_path.name), sm)
    return {"map": out.final(map_path.name), "report_data": out.final(data_name)}
