"""The rerun writer process of :mod:`sim.report.rerun`: a recording's rerun calls noted as
plain data (:class:`_Ops`, :class:`_Lazy`), pickled to a process that imports rerun beside
the simulation and replays them (:func:`_execute`), its failures sent back in one line."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path


def _one_line(text) -> str:
    return " ".join(str(text).split())


class _Lazy:
    """Stand-in for the ``rerun`` module: notes attribute chains and calls (``rr.Boxes3D(...)``,
    ``rr.components.FillMode.Solid``) as plain data, for :func:`_resolve` to replay."""

    def __init__(self, path: tuple = ()):
        self._path = path

    def __getattr__(self, name):
        if name.startswith("__"):
            raise AttributeError(name)
        return _Lazy(self._path + (name,))

    def __call__(self, *args, **kwargs):
        return _Call(self._path, args, kwargs)


@dataclass
class _Call:
    path: tuple
    args: tuple
    kwargs: dict


class _Ops:
    """Stand-in for a ``rr.RecordingStream``: notes ``log``, ``send_columns``, ... calls in order."""

    def __init__(self):
        self.calls = []

    def __getattr__(self, name):
        if name.startswith("_"):
            raise AttributeError(name)

        def note(*args, **kwargs):
            self.calls.append((name, args, kwargs))

        return note


def _resolve(rr, x):
    if isinstance(x, _Lazy):
        obj = rr
        for n in x._path:
            obj = getattr(obj, n)
        return obj
    if isinstance(x, _Call):
        return _resolve(rr, _Lazy(x.path))(*_resolve(rr, x.args), **_resolve(rr, x.kwargs))
    if isinstance(x, (list, tuple)):
        return type(x)(_resolve(rr, v) for v in x)
    if isinstance(x, dict):
        return {k: _resolve(rr, v) for k, v in x.items()}
    return x


def _escape(part: str) -> str:
    """An entity path part for ``part`` (as ``rr.escape_entity_path_part``, without importing rerun)."""
    out = []
    for c in part:
        if c.isalnum() or c in "_-.":
            out.append(c)
        elif c.isascii() and c.isprintable():
            out.append("\\" + c)
        else:
            out.append(f"\\u{{{ord(c):X}}}")
    return "".join(out)


def _execute(job: dict) -> None:
    """Replay a recording job (from :meth:`RrdTarget.write_run`) with rerun: sinks, blueprint, calls."""
    from types import SimpleNamespace

    from sim.report.rerun import DEFAULT_URL, _rerun, blueprint

    rr = _rerun()
    rec = rr.RecordingStream(job["application_id"], recording_id=job["recording_id"])
    acts, dofs, has_acc, has_cmp, has_spec = job["blueprint"]
    shape = SimpleNamespace(
        actuators=acts,
        dofs=dofs,
        accelerometers=() if has_acc else None,
        specimen_acceleration=() if has_spec else None,
    )
    bp = blueprint(shape, True if has_cmp else None)
    sinks = []
    if job.get("file"):
        try:
            sinks.append(rr.FileSink(job["file"]))
        except RuntimeError as exc:  # rerun reports the OS error in its message: "(os error 2)"
            import re

            m = re.search(r"os error (\d+)", str(exc))
            if m is None:
                raise
            raise OSError(int(m.group(1)), os.strerror(int(m.group(1)))) from None
    if job["spawn"]:
        rr.spawn(connect=False)
    if job["spawn"] or job["connect"] is not None:
        sinks.append(rr.GrpcSink(job["connect"] or DEFAULT_URL))
    done = False
    try:
        rec.set_sinks(*sinks, default_blueprint=bp)
        for name, args, kwargs in job["ops"]:
            getattr(rec, name)(*_resolve(rr, args), **_resolve(rr, kwargs))
        rec.flush()
        rec.disconnect()
        done = True
    finally:
        if not done:
            try:
                rec.disconnect()
            except Exception:  # noqa: BLE001 - best effort; the caller removes the partial file
                pass


_WORKER_CODE = "import sys; from sim.report.rerun_worker import _worker_main; sys.exit(_worker_main())"


def _start_worker():
    import subprocess
    import sys

    root = str(Path(__file__).resolve().parents[2])  # the repository (sim/report/rerun.py)
    env = dict(os.environ)
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return subprocess.Popen(
        [sys.executable, "-c", _WORKER_CODE],
        stdin=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        cwd=root,
        env=env,
    )


class ViewerTimeout(Exception):
    """No live viewer took the recording within the time allowed."""

    def __init__(self, timeout_s):
        super().__init__(f"no viewer answered within {timeout_s:g} s")
        self.timeout_s = timeout_s


def _stop_worker(proc) -> None:
    if proc.poll() is None:
        proc.kill()
    try:
        proc.communicate(timeout=10)
    except Exception:  # noqa: BLE001 - it was killed; nothing more to do
        pass


def _run_in_worker(proc, job: dict, timeout_s: float | None = None) -> None:
    """Hand ``job`` to the writer process and wait for it; its failure is raised here
    (OSError for a file that cannot be written, RuntimeError otherwise). With
    ``timeout_s`` (a live viewer), a worker still busy after that long is stopped and
    :class:`ViewerTimeout` raised: rerun waits for a viewer forever and, inside its own
    code, does not see Ctrl-C."""
    import pickle
    import subprocess

    try:
        _, err = proc.communicate(pickle.dumps(job, protocol=pickle.HIGHEST_PROTOCOL), timeout=timeout_s)
    except subprocess.TimeoutExpired:
        _stop_worker(proc)
        raise ViewerTimeout(timeout_s) from None
    if proc.returncode == 0:
        return
    lines = [ln for ln in err.decode("utf-8", "replace").splitlines() if ln.startswith(("OSError\t", "Error\t"))]
    if lines:
        kind, errno, msg = (lines[-1].split("\t", 2) + ["", ""])[:3]
        if kind == "OSError":
            raise OSError(int(errno or 0), msg)
        raise RuntimeError(f"the recording's writer process failed: {msg}")
    tail = _one_line(err.decode("utf-8", "replace")[-500:]) or f"exit code {proc.returncode}"
    raise RuntimeError(f"the recording's writer process failed: {tail}")


def _worker_main() -> int:
    """The writer process: import rerun at once, then read one pickled job on stdin and run it."""
    import pickle
    import sys

    try:
        import pyarrow as pa
        import rerun  # noqa: F401
        import rerun.blueprint  # noqa: F401

        pa.array([0.0]).to_numpy()
        try:  # pyarrow imports pandas on its first conversion of a NumPy array; do it now
            import pandas  # noqa: F401
        except ImportError:
            pass
    except Exception:  # noqa: BLE001 - _execute imports again and reports the failure
        pass
    data = sys.stdin.buffer.read()
    if not data:
        return 0  # the target was never written
    try:
        _execute(pickle.loads(data))
    except OSError as exc:
        sys.stderr.write(f"OSError\t{exc.errno or 0}\t{_one_line(exc.strerror or exc)}\n")
        return 1
    except Exception as exc:  # noqa: BLE001 - reported to the parent in one line
        sys.stderr.write(f"Error\t0\t{type(exc).__name__}: {_one_line(exc)}\n")
        return 1
    return 0
