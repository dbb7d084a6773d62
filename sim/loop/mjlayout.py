"""Where MuJoCo keeps the arrays the control callback reads (:mod:`sim.loop.callback`):
byte offsets of array pointers inside the ``mjData`` struct and of ``nuserdata`` inside
``mjModel``, found at run time by matching the Python binding's array addresses in the
structs' memory (no header layout is assumed)."""

from __future__ import annotations

import ctypes

import mujoco
import numpy as np

_offsets = None


def field_offsets(fields: tuple) -> dict:
    """Byte offsets of the array pointers of ``fields`` in MuJoCo's ``mjData`` struct,
    found by matching each field's address (from the binding) in the struct's memory,
    of ``nuserdata`` in ``mjModel`` (key ``"nuserdata"``), and of the first warning counter
    (``warning[0].number``, key ``"warning"``: the counters are inside the struct, not
    behind a pointer)."""
    global _offsets
    if _offsets is not None:
        return _offsets
    spec = mujoco.MjSpec()
    b = spec.worldbody.add_body()
    b.add_freejoint()
    b.add_geom(size=[0.1, 0, 0])
    spec.nuserdata = 3
    m = spec.compile()
    d = mujoco.MjData(m)
    ptrs = {f: getattr(d, f).ctypes.data for f in fields if f != "ctrl"}
    size = 1 << 20
    for size in (1 << 14, 1 << 16, 1 << 18, 1 << 20):
        words = np.frombuffer(ctypes.string_at(d._address, size), dtype=np.uint64)
        found = {f: np.flatnonzero(words == p) for f, p in ptrs.items()}
        if all(len(v) for v in found.values()):
            break
    # a second MjData (a model with an actuator, so ctrl exists) settles fields whose
    # address also sits in another slot (qpos is also the start of the state buffer)
    spec2 = mujoco.MjSpec()
    b2 = spec2.worldbody.add_body()
    b2.add_joint(name="h")
    b2.add_geom(size=[0.1, 0, 0])
    spec2.add_actuator(target="h", trntype=mujoco.mjtTrn.mjTRN_JOINT)
    spec2.nuserdata = 5
    m2 = spec2.compile()
    d2 = mujoco.MjData(m2)
    words2 = np.frombuffer(ctypes.string_at(d2._address, size), dtype=np.uint64)
    out = {}
    for f in fields:
        addr2 = getattr(d2, f).ctypes.data
        hits2 = set(np.flatnonzero(words2 == addr2).tolist())
        hits = hits2 & set(found[f].tolist()) if f in found else hits2
        if len(hits) != 1:
            hits = {h for h in hits if h == max(hits)}  # the field itself comes after buffer/arena starts
        if len(hits) != 1:
            raise RuntimeError(f"mjData field {f}: not found once in the struct")
        out[f] = int(hits.pop()) * 8
    # nuserdata in mjModel (an int): where two models differing only in it differ
    specs = []
    for nud in (3, 77777):
        sp = mujoco.MjSpec()
        sp.worldbody.add_body().add_geom(size=[0.1, 0, 0])
        sp.nuserdata = nud
        specs.append(sp.compile())
    a, b = (np.frombuffer(ctypes.string_at(mm._address, 4096), dtype=np.int32) for mm in specs)
    hits = np.flatnonzero((a == 3) & (b == 77777))
    if len(hits) != 1:
        raise RuntimeError("mjModel field nuserdata: not found once in the struct")
    out["nuserdata"] = int(hits[0]) * 4
    # the warning counters sit in the struct itself (mjWarningStat warning[mjNWARNING]): the
    # offset of warning[0].number, the same in both MjData
    ow = [dd.warning.number.ctypes.data - dd._address for dd in (d, d2)]
    if ow[0] != ow[1] or not 0 <= ow[0] < size:
        raise RuntimeError("mjData field warning: not at one offset in the struct")
    out["warning"] = int(ow[0])
    _offsets = out
    return out


__all__ = ["field_offsets"]
