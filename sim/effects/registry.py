"""Building a description's ``[[effect]]`` entries: the one registry
(:data:`sim.effects.base.EFFECTS`), the built-in library (:mod:`sim.effects.mechanical`)
and a user's own effects loaded from a Python file named in the description::

    [[effect]]
    type = "my_effects.py:Pickup"     # <file relative to the description>:<Effect subclass>
    where = "dof:x"
    gain = 2.0

The class is registered (as a subclass whose ``type`` is that string) under that type
string, so it is created, checked, written back and run like a built-in one (see
docs/effects.md).
"""

from __future__ import annotations

import difflib
import hashlib
import importlib.util
import sys
from pathlib import Path

from sim.effects import mechanical  # noqa: F401  (registers the built-in library)
from sim.effects.base import EFFECTS, Effect, create
from sim.effects.mechanical import dahl_step
from sim.errors import ScenarioError


def known() -> list[str]:
    """Every registered effect type."""
    return sorted(EFFECTS)


def description_folder(desc) -> Path:
    """The folder of the description file (its ``source`` up to a ``" ["`` tag), or the
    working directory for a description that did not come from a file."""
    src = str(getattr(desc, "source", "") or "").split(" [", 1)[0]
    p = Path(src)
    return p.parent if src and p.is_file() else Path.cwd()


def load_user_effect(kind: str, folder: Path, source: str = "effect") -> type[Effect]:
    """Load ``"file.py:Class"`` (file relative to ``folder``), check it is an
    :class:`Effect` subclass and register it under ``kind``; one-line error otherwise."""
    if kind in EFFECTS:
        return EFFECTS[kind]
    file, _, cls_name = kind.rpartition(":")
    path = (folder / file).resolve()
    if not path.is_file():
        raise ScenarioError(
            f"{source}: type = '{kind}': no file {path}; give the path of a .py file "
            "relative to the description, then ':' and the class name"
        )
    tag = hashlib.sha1(str(path).encode()).hexdigest()[:10]
    name = f"shaketable_user_effects_{tag}"
    try:
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    except Exception as e:  # noqa: BLE001 - any failure of the user's file is a user error
        sys.modules.pop(name, None)
        msg = str(e).splitlines()[0] if str(e) else ""
        raise ScenarioError(
            f"{source}: type = '{kind}': {path.name} does not load ({type(e).__name__}: {msg}); fix the file"
        ) from None
    cls = getattr(module, cls_name, None)
    if not (isinstance(cls, type) and issubclass(cls, Effect)):
        have = [n for n, v in vars(module).items() if isinstance(v, type) and issubclass(v, Effect) and v is not Effect]
        close = difflib.get_close_matches(cls_name, have, n=1)
        hint = (
            (f" (did you mean '{close[0]}'?)" if close else f"; its Effect classes: {', '.join(have)}")
            if have
            else "; it defines no subclass of sim.effects.Effect"
        )
        raise ScenarioError(f"{source}: type = '{kind}': '{cls_name}' in {path.name} is not an Effect{hint}")
    # registered as a subclass whose type is the entry's string, so that Effect.entry()
    # writes back a type that loads again (the user's class itself is left as it is)
    reg = type(cls.__name__, (cls,), {"type": kind, "__module__": cls.__module__, "__doc__": cls.__doc__})
    EFFECTS[kind] = reg
    return reg


def catalogue() -> list[dict]:
    """Every registered effect type: its places, whether it runs every step, its
    parameters (unit, bounds, default: None when required), its settings and its doc line."""
    out = []
    for kind in known():
        cls = EFFECTS[kind]
        doc = (cls.__doc__ or "").strip().split("\n\n")[0]
        out.append(
            {
                "type": kind,
                "places": list(cls.places),
                "per_step": bool(cls.per_step),
                "parameters": {
                    k: {"unit": u, "lower": lo, "upper": hi, "default": d} for k, (u, lo, hi, d) in cls.SPEC.items()
                },
                "settings": dict(cls.OPTIONS),
                "doc": " ".join(doc.split()),
            }
        )
    return out


def build_effects(spec, effects: list[dict], desc=None) -> tuple[list, list]:
    """Build a description's ``[[effect]]`` entries into ``spec``.

    Returns ``(step_effects, effects)``: the per-step ones (applied by the loop every
    physics step) and every :class:`sim.effects.base.Effect` (whose lifecycle the loop
    runs: ``edit_hydraulics``, ``bind``, ``reset``, ``apply``, ``measure``)."""
    steps, objs = [], []
    folder = description_folder(desc)
    for i, p in enumerate(effects or []):
        if not isinstance(p, dict) or "type" not in p:
            raise ScenarioError(f"effect[{i}] needs a 'type' (one of {', '.join(known())}, or 'file.py:Class')")
        kind = str(p["type"])
        src = f"{getattr(desc, 'source', 'description')}: effect[{i}]"
        if kind not in EFFECTS and ".py:" in kind:
            load_user_effect(kind, folder, src)
        e = create(p, source=src)
        e.edit_spec(spec, desc)
        objs.append(e)
        if e.per_step:
            steps.append(e)
    return steps, objs


def hydraulics_with(desc, effects=None):
    """``desc``'s :class:`hydraulics.params.HydraulicParams` with its effects' edits applied
    (``edit_hydraulics``): ``effects`` built (a compiled model's ``tm.effects``), else the
    description's own entries of the registered types that edit the hydraulics, created
    here without compiling a model."""
    from hydraulics.params import HydraulicParams

    hp = HydraulicParams.from_table(desc.raw)
    if effects is None:
        entries = [e for e in desc.raw.get("effect", []) or [] if isinstance(e, dict)]
        hydraulic = [e for e in entries if e.get("type") in EFFECTS]
        hydraulic = [e for e in hydraulic if EFFECTS[e["type"]].edit_hydraulics is not Effect.edit_hydraulics]
        effects = [create(e, source=f"{desc.source}: effect") for e in hydraulic]
    for e in effects:
        hp = e.edit_hydraulics(hp)
    return hp


__all__ = [
    "build_effects",
    "hydraulics_with",
    "catalogue",
    "dahl_step",
    "description_folder",
    "known",
    "load_user_effect",
]
