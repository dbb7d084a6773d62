"""The one comment-keeping writer of table descriptions.

Every calibration command rewrites a table's TOML file the same way: values are
rewritten in place on their own line (the line's comment, the file's other comments and
layout kept), ``[[effect]]`` entries are added after the last one (or at the end) or
replaced where an entry of the same ``type`` and ``where`` already is. Every line it
writes carries its source (``calibrated: ...``), as the house rules ask.

:class:`TomlText` holds the text; ``set_value``/``set_effect`` edit it; ``save`` writes it
atomically. The result is checked to parse (``tomllib``) before it is written.
"""

from __future__ import annotations

import json
import math
import re
import tomllib
from pathlib import Path

from sim.errors import UserError

_HEADER = re.compile(r"^\s*\[+([^\]]+)\]+\s*(#.*)?$")


class DescriptionWriteError(UserError):
    """A value that cannot be rewritten in a description file (key missing, bad TOML)."""


def format_value(v) -> str:
    """A TOML literal of a number, string, bool or list of them."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise DescriptionWriteError(f"cannot write the non-finite value {v!r} into a description")
        return f"{v:.6g}" if ("e" in f"{v:.6g}" or "." in f"{v:.6g}") else f"{v:.6g}.0"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(format_value(x) for x in v) + "]"
    raise DescriptionWriteError(f"cannot write a {type(v).__name__} into a description")


def _line(key: str, value_text: str, comment: str | None) -> str:
    body = f"{key} = {value_text}"
    return body.ljust(36) + f"# {comment}" if comment else body


class TomlText:
    """A description file's text, edited line by line."""

    def __init__(self, text: str, source: str = "<description>"):
        self.lines = text.split("\n")
        self.source = source

    @classmethod
    def read(cls, path) -> "TomlText":
        from sim.runs.runfile import source_text  # a file, or the text a run carries

        return cls(source_text(str(path)), str(path))

    @property
    def text(self) -> str:
        return "\n".join(self.lines)

    # ------------------------------------------------------------------ plain keys
    def key_index(self, section: str, key: str) -> int | None:
        """Line of ``key = ...`` in ``[section]`` (the first ``[[section]]`` entry for arrays)."""
        current = None
        for i, line in enumerate(self.lines):
            h = _HEADER.match(line)
            if h:
                current = h.group(1).strip()
                continue
            if current == section and re.match(rf"^\s*{re.escape(key)}\s*=", line):
                return i
        return None

    def old_comment(self, i: int) -> str:
        m = re.match(r"^[^#]*#\s*(.*)$", self.lines[i])
        return m.group(1).strip() if m else ""

    def set_value(
        self,
        section: str,
        key: str,
        value,
        comment: str | None = None,
        *,
        value_text: str | None = None,
        keep_comment: bool = False,
        create: bool = False,
    ) -> None:
        """Rewrite ``[section] key`` in place. ``comment``: the new source comment (with
        ``keep_comment`` the old comment is appended after it); ``create``: add the key
        (and the section at the end) when missing."""
        vt = value_text if value_text is not None else format_value(value)
        i = self.key_index(section, key)
        if i is None:
            if not create:
                raise DescriptionWriteError(
                    f"{self.source}: cannot find {section}.{key} to rewrite; add the key to the file first"
                )
            j = self._section_end(section)
            if j is None:
                self.lines = self._rstrip() + ["", f"[{section}]", _line(key, vt, comment)]
            else:
                self.lines.insert(j, _line(key, vt, comment))
            return
        old = self.old_comment(i)
        if comment is None:
            comment = old or None
        elif keep_comment and old and old != comment:
            comment = f"{comment}; {old}"
        self.lines[i] = _line(key, vt, comment)

    def _section_end(self, section: str) -> int | None:
        start = None
        for i, line in enumerate(self.lines):
            h = _HEADER.match(line)
            if h and start is not None:
                return self._back_over_blank(i)
            if h and h.group(1).strip() == section:
                start = i
        return None if start is None else self._back_over_blank(len(self.lines))

    def _back_over_blank(self, i: int) -> int:
        while i > 0 and (not self.lines[i - 1].strip() or self.lines[i - 1].lstrip().startswith("#")):
            i -= 1
        return i

    def _rstrip(self) -> list[str]:
        out = list(self.lines)
        while out and not out[-1].strip():
            out.pop()
        return out

    # ------------------------------------------------------------------ [[effect]] entries
    def effect_blocks(self) -> list[tuple[int, int, dict]]:
        """``(first line, end line, parsed entry)`` of every ``[[effect]]`` entry."""
        heads = [i for i, line in enumerate(self.lines) if _HEADER.match(line)]
        out = []
        for n, i in enumerate(heads):
            if not re.match(r"^\s*\[\[\s*effect\s*\]\]", self.lines[i]):
                continue
            end = heads[n + 1] if n + 1 < len(heads) else len(self.lines)
            end = self._back_over_blank(end) if end > i + 1 else end
            end = max(end, i + 1)
            body = "\n".join(self.lines[i + 1 : end])
            try:
                entry = tomllib.loads(body)
            except tomllib.TOMLDecodeError as e:
                raise DescriptionWriteError(
                    f"{self.source}: the [[effect]] entry at line {i + 1} is not TOML ({e})"
                ) from None
            out.append((i, end, entry))
        return out

    def set_effect(self, entry: dict, *, comments: dict | None = None) -> str:
        """Add ``entry`` as an ``[[effect]]`` (after the last one, or at the end; a
        ``foundation_mode`` before the first, :func:`sim.calibrate.paths.build_order`), or rewrite
        the entry with the same ``type``, ``where`` and ``name`` in place (its comments kept).
        ``comments``: key -> source comment. Returns ``"added"`` or ``"replaced"``."""
        if "type" not in entry or "where" not in entry:
            raise DescriptionWriteError(f"{self.source}: an [[effect]] entry needs 'type' and 'where'")
        comments = comments or {}
        blocks = self.effect_blocks()
        for i, end, old in blocks:
            if (old.get("type"), old.get("where"), old.get("name")) == (
                entry["type"],
                entry["where"],
                entry.get("name"),
            ):
                for k, v in entry.items():
                    if k in ("type", "where", "name"):
                        continue
                    j = next(
                        (n for n in range(i + 1, end) if re.match(rf"^\s*{re.escape(k)}\s*=", self.lines[n])), None
                    )
                    line = _line(k, format_value(v), comments.get(k))
                    if j is None:
                        self.lines.insert(end, line)
                        end += 1
                    else:
                        old_c = self.old_comment(j)
                        c = comments.get(k) or old_c or None
                        self.lines[j] = _line(k, format_value(v), c)
                return "replaced"
        new = ["", "[[effect]]"] + [_line(k, format_value(v), comments.get(k)) for k, v in entry.items()]
        if blocks and entry["type"] == "foundation_mode":
            # before the first: it must be built before the DOF effects that make tendons
            at = blocks[0][0]
            self.lines[at:at] = new[1:] + [""]
        elif blocks:
            at = blocks[-1][1]
            self.lines[at:at] = new
        else:
            self.lines = self._rstrip() + new + [""]
        return "added"

    # ------------------------------------------------------------------ output
    def check(self) -> dict:
        try:
            return tomllib.loads(self.text)
        except tomllib.TOMLDecodeError as e:
            raise DescriptionWriteError(
                f"{self.source}: the rewritten description is not TOML ({e}); nothing written"
            ) from None

    def save(self, path) -> Path:
        """Write atomically (after checking that the text parses)."""
        from sim.runs.files import write_text_atomic

        self.check()
        p = Path(path)
        text = self.text if self.text.endswith("\n") else self.text + "\n"
        write_text_atomic(p, text)
        return p


def changed_values(old: dict, new: dict, prefix: str = "") -> list[tuple[str, str, object]]:
    """``(section, key, new value)`` of every scalar (or list of scalars) that differs
    between two parsed descriptions (tables only; arrays of tables are not compared)."""
    out = []
    for k, v in new.items():
        if isinstance(v, dict):
            out += changed_values(
                old.get(k, {}) if isinstance(old.get(k), dict) else {}, v, f"{prefix}.{k}" if prefix else k
            )
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            continue
        elif prefix and old.get(k) != v:
            out.append((prefix, k, v))
    return out


__all__ = ["DescriptionWriteError", "TomlText", "changed_values", "format_value"]
