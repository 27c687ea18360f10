"""The feature grammar of the ``aux_response`` effect kind (docs/formats.md): a rate
error that is a sparse sum of terms, each a coefficient (deg/h per unit of the feature)
times a feature of the measured conditions. One grammar, used by the model file, the
simulator, ``fogmon explain`` and its report:

- ``NAME``: an aux column, or another axis's rate column (``rate_x_dph``: that axis's
  measured rate, deg/h);
- ``NAME^2``, ``abs(NAME)``;
- ``d(NAME)/dt``: per second, of the channel smoothed by a trailing moving average over
  ``smooth_s`` s, by 3-point backward differences with step ``diff_step_s`` s (the
  ``thermal_drift`` kind's derivative, ``fogmon.sim.effects.temperature_derivatives``);
- ``NAME*NAME2``: the product of two channels.

NAME is letters, digits and ``_``, starting with a letter. ``parse_feature`` gives the
canonical text (no spaces), ``validate_terms`` checks a list of term tables with
one-line errors naming the file and the term, ``feature_unit`` / ``coef_unit`` give the
units from the channels' (``fogmon.units.channel_unit``). The values of a feature:
``fogmon.sim.effects.feature_values``."""
from __future__ import annotations

import difflib
import math
import re
from dataclasses import dataclass

from fogmon.errors import FogmonError
from fogmon.units import channel_unit

_NAME = r"[A-Za-z][A-Za-z0-9_]*"
_SHAPES = (
    ("square", re.compile(rf"({_NAME})\^2")),
    ("abs", re.compile(rf"abs\(({_NAME})\)")),
    ("rate", re.compile(rf"d\(({_NAME})\)/dt")),
    ("product", re.compile(rf"({_NAME})\*({_NAME})")),
    ("linear", re.compile(rf"({_NAME})")),
)
#: the grammar in words, for error messages
GRAMMAR = "NAME, NAME^2, abs(NAME), d(NAME)/dt or NAME*NAME2"
#: a rate column of another axis (docs/formats.md, several axes)
RATE_COLUMN = re.compile(r"rate_([A-Za-z0-9]+)_dph")
#: keys of a term table: required, then optional
TERM_KEYS = ("feature", "coef", "coef_lo", "coef_hi", "unit", "physics", "colinear")


@dataclass(frozen=True)
class Feature:
    """A parsed feature: ``shape`` ("linear", "square", "abs", "rate", "product") of the
    channels ``names`` (two for a product, else one)."""

    shape: str
    names: tuple[str, ...]

    @property
    def text(self) -> str:
        """The canonical text (``vib_g^2``)."""
        a = self.names[0]
        return {"linear": a, "square": f"{a}^2", "abs": f"abs({a})", "rate": f"d({a})/dt",
                "product": "*".join(self.names)}[self.shape]


def parse_feature(text: object, where: str = "feature") -> Feature:
    """The Feature of ``text`` (spaces ignored); a one-line FogmonError naming ``where``
    and the text when it is not of the grammar."""
    if not isinstance(text, str):
        raise FogmonError(f"{where}: a feature is a string ({GRAMMAR}), got {text!r}")
    s = "".join(text.split())
    for shape, rx in _SHAPES:
        m = rx.fullmatch(s)
        if m:
            return Feature(shape, m.groups())
    raise FogmonError(f"{where}: feature {text!r} is not one of {GRAMMAR} (NAME: letters, digits, _)")


def other_axis(name: str) -> str | None:
    """The axis whose rate column ``name`` is (``rate_x_dph`` -> "x"), else None."""
    m = RATE_COLUMN.fullmatch(name)
    return m.group(1) if m else None


def feature_unit(f: Feature, meta: dict | None = None) -> str:
    """The feature's unit from its channels' (``channel_unit``; "unit of NAME" when a
    channel's name does not say)."""
    a = _unit(f.names[0], meta)
    if f.shape in ("linear", "abs"):
        return a
    if f.shape == "square":
        return f"{_paren(a)}^2"
    if f.shape == "rate":
        return f"{_paren(a)}/s"
    return f"{_paren(a)}*{_paren(_unit(f.names[1], meta))}"


def _unit(name: str, meta: dict | None) -> str:
    return channel_unit(name, meta)[1] or f"unit of {name}"


def _paren(unit: str) -> str:
    return f"({unit})" if " " in unit or "/" in unit else unit


def coef_unit(f: Feature, meta: dict | None = None) -> str:
    """The unit of a coefficient of ``f``: deg/h per the feature's unit."""
    return f"deg/h per {feature_unit(f, meta)}"


def channels_of(terms: list[dict]) -> list[str]:
    """Every channel the terms' features read, in order, once."""
    out: dict[str, None] = {}
    for t in terms:
        for name in parse_feature(t["feature"]).names:
            out[name] = None
    return list(out)


def _finite(v: object, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
        raise FogmonError(f"{where}: expected a finite number, got {v!r}")
    return float(v)


def validate_terms(terms: object, where: str) -> list[dict]:
    """The normalized terms of an ``aux_response`` effect: each a table with ``feature``
    (the grammar; canonical text) and ``coef`` (deg/h per feature unit), optional
    ``coef_lo``/``coef_hi`` (its 95 % interval; default: coef), ``unit`` (default: from
    the channels' names), ``physics`` (text, default "") and ``colinear`` (features the
    data could not tell from this one, default []). One-line errors name ``where`` and
    the term."""
    if not isinstance(terms, (list, tuple)) or not terms:
        raise FogmonError(f"{where}: parameter 'terms' must be a non-empty list of tables "
                          f"{{feature = \"vib_g^2\", coef = 0.07, ...}}, got {terms!r}")
    out, seen = [], set()
    for i, t in enumerate(terms):
        at = f"{where}: terms[{i}]"
        if not isinstance(t, dict):
            raise FogmonError(f"{at}: must be a table {{feature = ..., coef = ...}}, got {t!r}")
        for k in t:
            if k not in TERM_KEYS:
                close = difflib.get_close_matches(str(k), TERM_KEYS, n=1, cutoff=0.5)
                raise FogmonError(f"{at}: unknown key {k!r} (expected: {', '.join(TERM_KEYS)})"
                                  + (f"; did you mean {close[0]!r}?" if close else ""))
        for k in ("feature", "coef"):
            if k not in t:
                raise FogmonError(f"{at}: missing key {k!r}")
        f = parse_feature(t["feature"], at)
        at = f"{where}: term {f.text!r}"
        if f.text in seen:
            raise FogmonError(f"{at}: the feature appears twice")
        seen.add(f.text)
        coef = _finite(t["coef"], f"{at}: coef")
        lo = _finite(t.get("coef_lo", coef), f"{at}: coef_lo")
        hi = _finite(t.get("coef_hi", coef), f"{at}: coef_hi")
        if not lo <= coef <= hi:
            raise FogmonError(f"{at}: coef_lo <= coef <= coef_hi expected, got {lo:g}, {coef:g}, {hi:g}")
        unit, physics = t.get("unit", coef_unit(f)), t.get("physics", "")
        for k, v in (("unit", unit), ("physics", physics)):
            if not isinstance(v, str):
                raise FogmonError(f"{at}: {k} must be a string, got {v!r}")
        colinear = t.get("colinear", [])
        if not isinstance(colinear, (list, tuple)):
            raise FogmonError(f"{at}: colinear must be a list of features, got {colinear!r}")
        out.append({"feature": f.text, "coef": coef, "coef_lo": lo, "coef_hi": hi, "unit": unit,
                    "physics": physics, "colinear": [parse_feature(c, f"{at}: colinear").text for c in colinear]})
    return out


def term_text(term: dict) -> str:
    """One term of a fitted ``aux_response`` in words: "vibration rectification: bias
    follows vib_g^2, 0.0712 deg/h per g^2 [0.065, 0.077]" (95 % interval; a coefficient in
    deg/h per deg/h - another axis's rate - also as an angle in mrad); without a physics
    name "bias follows <feature>, <coef> <unit>"."""
    c, lo, hi = term["coef"], term["coef_lo"], term["coef_hi"]
    text = f"bias follows {term['feature']}, {c:.4g} {term['unit']}"
    if lo != hi:
        text += f" [{lo:.3g}, {hi:.3g}]"
    if term["unit"] == "deg/h per deg/h":
        text += f" ({1e3 * c:.3g} mrad)"
    return f"{term['physics']}: {text}" if term["physics"] else text
