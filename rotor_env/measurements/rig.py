"""The rig description: how a test rig's recordings map onto the model.

A YAML or JSON file; every key is optional except the probes.  A one-plane rig with
two probes and a keyphasor needs three lines::

    keyphasor: kp                 # column of the once-per-revolution pulse
    probes: {x: 45, y: -45}       # column -> mounting angle (degrees)
    units: {displacement: um}

The full set, with defaults::

    time: t                       # column of time
    units:
      time: s                     # s | ms
      displacement: um            # um | mil | mm | m | V | mV
      sensitivity_mv_per_um: 7.87 # needed for V / mV (API 670: 7.87 mV/um = 200 mV/mil)
      speed: rpm                  # rpm | rad/s | hz (for a speed column)
    keyphasor: kp                 # or ...
    speed: null                   # ... a speed column (spin angle by integration)
    keyphasor_threshold: null     # default: halfway between the pulse's low and high levels
    probes:                       # a list for two planes:
      - {name: x1, angle_deg: 45, plane: A}
      - {name: y1, angle_deg: -45, plane: A}
      - {name: x2, angle_deg: 45, plane: B}
      - {name: y2, angle_deg: -45, plane: B}
    planes: {A: {axial_position_m: 0.0}, B: {axial_position_m: 0.25}}
    model: auto                   # translation (one plane, Jeffcott, ip = 0) | tilt (two planes) | auto
    disk: {ip: 0.0}               # or polar_inertia_kg_m2 and diametral_inertia_kg_m2; mass_kg
    slow_roll_rpm: null           # runout taken from the revolutions below this speed

**Angles** are measured from the reference direction (e.g. top dead centre) *in the
direction of rotation*, in degrees.  The model's ``u`` axis is the reference, ``v`` is
90 degrees further in the direction of rotation, so a forward whirl turns from ``u`` to
``v`` (docs/PHYSICS.md 1.2: ``z = u + i v = th_y + i th_x``).  A probe reads the
displacement towards itself, ``p = u cos(angle) + v sin(angle)``.

Every error names the file and the key (``probes[1].angle_deg``).
"""

from __future__ import annotations

import json
import math
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["DISPLACEMENT_UNITS", "Probe", "Rig", "RigError", "load_rig"]

#: displacement unit -> metres (V and mV divide by the sensitivity first)
DISPLACEMENT_UNITS: dict[str, float] = {"um": 1e-6, "µm": 1e-6, "mil": 25.4e-6, "mm": 1e-3, "m": 1.0}
VOLT_UNITS: dict[str, float] = {"V": 1000.0, "mV": 1.0}  # -> mV
TIME_UNITS: dict[str, float] = {"s": 1.0, "ms": 1e-3}
SPEED_UNITS: dict[str, float] = {"rpm": 2.0 * math.pi / 60.0, "rad/s": 1.0, "hz": 2.0 * math.pi}
#: two probes of a plane closer than this (mod 180 degrees) cannot resolve the orbit
MIN_PROBE_SEPARATION_DEG = 20.0
_TOP_KEYS = {"time", "units", "keyphasor", "speed", "keyphasor_threshold", "probes", "planes", "model", "disk",
             "slow_roll_rpm"}


class RigError(ValueError):
    """A rig description that cannot be used as it is."""


@dataclass(frozen=True)
class Probe:
    """One proximity probe: its column, mounting angle (rad, in the direction of rotation) and plane."""

    name: str
    angle: float
    plane: str = "A"


@dataclass(frozen=True)
class Rig:
    """A validated rig description (see the module docstring for the file format)."""

    probes: tuple[Probe, ...]
    keyphasor: str | None = "kp"
    speed: str | None = None
    time: str = "t"
    time_unit: str = "s"
    displacement: str = "um"
    sensitivity_mv_per_um: float | None = None
    speed_unit: str = "rpm"
    keyphasor_threshold: float | None = None
    planes: dict[str, float] = field(default_factory=dict)  #: plane -> axial position (m)
    model: str = "translation"
    ip: float = 0.0
    mass_kg: float | None = None
    slow_roll_rpm: float | None = None
    source: str = ""

    @property
    def plane_names(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(p.plane for p in self.probes))

    def to_metres(self, value):
        """Probe reading (in the rig's displacement unit) -> metres."""
        if self.displacement in VOLT_UNITS:
            return value * VOLT_UNITS[self.displacement] / self.sensitivity_mv_per_um * 1e-6
        return value * DISPLACEMENT_UNITS[self.displacement]

    @property
    def amp_unit(self) -> str:
        """The unit results are reported in (volts are reported in um)."""
        return "um" if self.displacement in VOLT_UNITS or self.displacement == "µm" else self.displacement

    @classmethod
    def one_plane(cls, angles: dict[str, float], **kwargs) -> Rig:
        """A one-plane rig from ``{probe column: angle in degrees}``."""
        return _build({"probes": dict(angles), **kwargs}, "<rig>")


#: a rig description is a few lines: a file beyond this is not one (and is not read whole)
MAX_RIG_BYTES = 1_000_000
#: nesting deeper than this is no rig description (and would exhaust the parser's recursion)
MAX_RIG_DEPTH = 8
#: a value shown in an error message is cut to this many characters
SHOW_CHARS = 80


def _show(value) -> str:
    """``repr(value)`` cut to :data:`SHOW_CHARS` (a hostile file's value is never echoed whole)."""
    try:
        text = repr(value)
    except ValueError:  # an int too long for repr
        text = f"<a number of more than {sys.get_int_max_str_digits()} digits>"
    return text if len(text) <= SHOW_CHARS else text[: SHOW_CHARS - 15] + f"... ({len(text)} chars)"


def _yaml_loader():
    """A safe YAML loader that refuses anchors and aliases (a few hundred bytes of aliases
    expand to gigabytes) and nesting deeper than :data:`MAX_RIG_DEPTH`."""
    import yaml

    class RigLoader(yaml.SafeLoader):
        depth = 0

        def compose_node(self, parent, index):
            event = self.peek_event()
            where = f"line {event.start_mark.line + 1}, column {event.start_mark.column + 1}"
            if isinstance(event, yaml.AliasEvent) or getattr(event, "anchor", None) is not None:
                raise RigError(f"{where}: YAML anchors and aliases (&, *) are not accepted in a rig description; "
                               "write the values out")
            self.depth += 1
            if self.depth > MAX_RIG_DEPTH:
                raise RigError(f"{where}: nested more than {MAX_RIG_DEPTH} levels deep: not a rig description")
            try:
                return super().compose_node(parent, index)
            finally:
                self.depth -= 1

    return RigLoader


def load_rig(path: str | os.PathLike) -> Rig:
    """Read and validate a rig description (``.yaml``/``.yml`` or ``.json``)."""
    path = Path(path)
    if not path.is_file():
        raise RigError(f"{path}: no such rig description")
    try:
        with open(path, "rb") as fh:
            data = fh.read(MAX_RIG_BYTES + 1)
    except OSError as exc:
        raise RigError(f"{path}: cannot read the rig description ({exc.strerror or exc})") from None
    if len(data) > MAX_RIG_BYTES:
        raise RigError(f"{path}: larger than {MAX_RIG_BYTES // 1000} kB: not a rig description (a few lines of YAML "
                       "or JSON)")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise RigError(f"{path}, line {line}: not a text (UTF-8) file ({exc.reason} at byte {exc.start})") from None
    if path.suffix.lower() in (".yaml", ".yml"):
        try:
            import yaml
        except ImportError:  # pragma: no cover - pyyaml is a dependency
            raise RigError(f"{path}: reading YAML needs pyyaml (pip install pyyaml), or write the rig as JSON") from None
        try:
            raw = yaml.load(text, Loader=_yaml_loader())
        except RigError as exc:
            raise RigError(f"{path}, {exc}") from None
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            where = f", line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
            problem = getattr(exc, "problem", None) or str(exc)
            raise RigError(f"{path}{where}: not valid YAML ({_cut(str(problem))})") from None
        except RecursionError:
            raise RigError(f"{path}: nested too deeply: not a rig description") from None
    else:
        try:
            raw = json.loads(text)
        except json.JSONDecodeError as exc:
            raise RigError(f"{path}: not valid JSON (line {exc.lineno}: {exc.msg})") from None
        except RecursionError:
            raise RigError(f"{path}: nested too deeply: not a rig description") from None
        if _depth(raw) > MAX_RIG_DEPTH:
            raise RigError(f"{path}: nested more than {MAX_RIG_DEPTH} levels deep: not a rig description")
    if not isinstance(raw, dict):
        raise RigError(f"{path}: a rig description is a mapping of keys (probes, keyphasor, units, ...)")
    return _build(raw, str(path))


def _cut(text: str) -> str:
    return text if len(text) <= 4 * SHOW_CHARS else text[: 4 * SHOW_CHARS] + "..."


def _depth(x, level: int = 1) -> int:
    if isinstance(x, dict):
        return max((_depth(v, level + 1) for v in x.values()), default=level)
    if isinstance(x, list):
        return max((_depth(v, level + 1) for v in x), default=level)
    return level


def _number(where: str, key: str, value, *, allow_none: bool = False, positive: bool = False) -> float | None:
    """A finite number (``positive``: above zero); ``None`` passes with ``allow_none``."""
    if value is None and allow_none:
        return None
    if isinstance(value, bool):  # YAML reads yes/no/true/false as booleans: never a number here
        raise RigError(f"{where}: key {key!r}: {value!r} is a yes/no value, not a number")
    if not isinstance(value, (int, float, str)):
        raise RigError(f"{where}: key {key!r}: {_show(value)} is not a number")
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        raise RigError(f"{where}: key {key!r}: {_show(value)} is not a number (or beyond the float range)") from None
    if not math.isfinite(v) or (positive and v <= 0):
        raise RigError(f"{where}: key {key!r}: {_show(value)} must be a {'positive' if positive else 'finite'} "
                       "number")
    return v


def _name(where: str, key: str, value, *, allow_none: bool = False) -> str | None:
    """A column name: text (a number is taken as its text); never a list, a mapping or yes/no."""
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, (str, int)):
        raise RigError(f"{where}: key {key!r}: {_show(value)} is not a column name")
    name = str(value)
    if not name.strip() or len(name) > 200:
        raise RigError(f"{where}: key {key!r}: {_show(value)} is not a column name (empty or over 200 characters)")
    return name


def _positive(where: str, key: str, value, *, allow_none: bool = False) -> float | None:
    """A positive number; ``None`` passes with ``allow_none``."""
    return _number(where, key, value, allow_none=allow_none, positive=True)


def _in_range(where: str, key: str, value, lo: float, hi: float, says: str, *, below_hi: bool = False) -> float:
    """A finite number in ``[lo, hi]`` (``below_hi``: ``[lo, hi)``); ``says`` (``{v}``: the
    number) tells what is wrong with one outside."""
    v = _number(where, key, value)
    if not (lo <= v < hi if below_hi else lo <= v <= hi):
        raise RigError(f"{where}: key {key!r}: " + says.format(v=v))
    return v


def _choice(where: str, key: str, value, options) -> str:
    """One of ``options`` (names)."""
    if not isinstance(value, str) or value not in options:
        raise RigError(f"{where}: key {key!r}: {_show(value)} is not one of {', '.join(map(str, options))}")
    return value


def _section(where: str, raw: dict, key: str, known: tuple[str, ...], hint: str = "") -> dict:
    """The mapping under ``key`` (empty when absent), with no key outside ``known``."""
    value = raw.get(key) or {}
    if not isinstance(value, dict):
        raise RigError(f"{where}: key {key!r} must be a mapping{hint}")
    bad = sorted(map(str, set(value) - set(known)))
    if bad:
        raise RigError(f"{where}: unknown key(s) under {key!r}: {_show(bad)}")
    return value


def _build(raw: dict, where: str) -> Rig:
    unknown = sorted(map(str, set(raw) - _TOP_KEYS))
    if unknown:
        raise RigError(f"{where}: unknown key(s) {_show(unknown)}; known: {sorted(_TOP_KEYS)}")
    unit_keys = ("time", "displacement", "speed", "sensitivity_mv_per_um")
    units = _section(where, raw, "units", unit_keys, f" ({', '.join(unit_keys)})")
    time_unit = _choice(where, "units.time", units.get("time", "s"), TIME_UNITS)
    disp = _choice(where, "units.displacement", units.get("displacement", "um"), (*DISPLACEMENT_UNITS, *VOLT_UNITS))
    sens = _positive(where, "units.sensitivity_mv_per_um", units.get("sensitivity_mv_per_um"), allow_none=True)
    if disp in VOLT_UNITS and sens is None:
        raise RigError(f"{where}: key 'units.sensitivity_mv_per_um' is needed for displacement in {disp} "
                       "(API 670 probes: 7.87 mV/um)")
    speed_unit = _choice(where, "units.speed", units.get("speed", "rpm"), SPEED_UNITS)
    probes_raw = raw.get("probes")
    if probes_raw is None:
        raise RigError(f"{where}: key 'probes' is missing (e.g. probes: {{x: 45, y: -45}})")
    items: list[dict] = []
    if isinstance(probes_raw, dict):
        for name, ang in probes_raw.items():
            items.append({"name": name, "angle_deg": ang})
    elif isinstance(probes_raw, list):
        items = probes_raw
    else:
        raise RigError(f"{where}: key 'probes' must be a mapping name -> angle or a list of probes")
    if not items:
        raise RigError(f"{where}: key 'probes' is empty; an orbit needs an X-Y pair (e.g. probes: {{x: 45, y: -45}})")
    probes = []
    probe_z: dict[str, float] = {}  # axial positions given per probe
    for i, item in enumerate(items):
        key = f"probes[{i}]" if isinstance(probes_raw, list) else f"probes.{str(item.get('name'))[:SHOW_CHARS]}"
        if not isinstance(item, dict) or "name" not in item or "angle_deg" not in item:
            raise RigError(f"{where}: key {key!r}: each probe needs 'name' and 'angle_deg'")
        extra = sorted(map(str, set(item) - {"name", "angle_deg", "plane", "axial_position_m"}))
        if extra:
            raise RigError(f"{where}: key {key!r}: unknown key(s) {_show(extra)}")
        ang = _in_range(where, f"{key}.angle_deg", item["angle_deg"], -360.0, 360.0,
                        "{v:g} is not an angle in degrees (-360..360)")
        probes.append(Probe(_name(where, f"{key}.name", item["name"]), math.radians(ang),
                            _name(where, f"{key}.plane", item.get("plane", "A"))))
        if "axial_position_m" in item:
            z = _number(where, f"{key}.axial_position_m", item["axial_position_m"])
            z_plane = probe_z.setdefault(probes[-1].plane, z)
            if z_plane != z:
                raise RigError(f"{where}: key '{key}.axial_position_m': {z:g} m, but plane {probes[-1].plane!r} "
                               f"is at {z_plane:g} m (its other probe): a plane has one axial position")
    names = [p.name for p in probes]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise RigError(f"{where}: key 'probes': probe name(s) {sorted(dup)} appear more than once")
    planes_raw = raw.get("planes") or {}
    planes: dict[str, float] = {}
    for pl in dict.fromkeys(p.plane for p in probes):
        members = [p for p in probes if p.plane == pl]
        if len(members) < 2:
            raise RigError(f"{where}: key 'probes': plane {pl!r} has {len(members)} probe; an orbit needs two "
                           "(an X-Y pair)")
        a, b = members[0], members[1]
        sep = abs(math.degrees(a.angle - b.angle)) % 180.0
        if min(sep, 180.0 - sep) < MIN_PROBE_SEPARATION_DEG:
            raise RigError(f"{where}: key 'probes' ({a.name}, {b.name}): mounting angles "
                           f"{math.degrees(a.angle):g} and {math.degrees(b.angle):g} deg are (nearly) collinear; "
                           "an X-Y pair is mounted 90 deg apart")
        if not isinstance(planes_raw, dict):
            raise RigError(f"{where}: key 'planes' must be a mapping plane -> {{axial_position_m: z}}")
        pos = planes_raw.get(pl, {})
        if not isinstance(pos, dict):
            raise RigError(f"{where}: key 'planes.{pl}': {_show(pos)} is not a mapping "
                           "(e.g. planes: {A: {axial_position_m: 0.0}})")
        planes[pl] = _number(where, f"planes.{pl}.axial_position_m",
                             pos.get("axial_position_m", probe_z.get(pl, 0.0)))
    bad = sorted(map(str, set(planes_raw) - set(planes))) if isinstance(planes_raw, dict) else []
    if bad:
        raise RigError(f"{where}: key 'planes': plane(s) {_show(bad)} have no probe (the probes' planes: "
                       f"{sorted(planes)})")
    model = raw.get("model", "auto")
    _choice(where, "model", model, ("auto", "translation", "tilt"))
    if model == "auto":
        model = "tilt" if len(planes) >= 2 else "translation"
    if model == "tilt":
        if len(planes) != 2:
            raise RigError(f"{where}: key 'model': tilt needs exactly two measurement planes, the rig has {len(planes)}")
        z = list(planes.values())
        if abs(z[1] - z[0]) <= 0:
            raise RigError(f"{where}: key 'planes': the two planes need different axial_position_m for the tilt")
    disk = _section(where, raw, "disk", ("ip", "polar_inertia_kg_m2", "diametral_inertia_kg_m2", "mass_kg"))
    if "ip" in disk:
        ip = _number(where, "disk.ip", disk["ip"])
    elif "polar_inertia_kg_m2" in disk or "diametral_inertia_kg_m2" in disk:
        ipol = _positive(where, "disk.polar_inertia_kg_m2", disk.get("polar_inertia_kg_m2"))
        idia = _positive(where, "disk.diametral_inertia_kg_m2", disk.get("diametral_inertia_kg_m2"))
        ip = ipol / idia
    else:
        ip = 0.0
    if model == "translation":
        ip = 0.0  # the Jeffcott rotor's translation has no gyroscopic coupling
    ip = _in_range(where, "disk", ip, 0.0, 1.0, "inertia ratio ip = {v:g} must be in [0, 1) for this model "
                   "(a disk with I_p >= I_t has no forward critical)", below_hi=True)
    mass = _positive(where, "disk.mass_kg", disk.get("mass_kg"), allow_none=True)
    kp = _name(where, "keyphasor", raw.get("keyphasor", None), allow_none=True)
    sp = _name(where, "speed", raw.get("speed", None), allow_none=True)
    if kp is None and sp is None:
        kp = "kp"
    if kp is not None and sp is not None:
        raise RigError(f"{where}: keys 'keyphasor' and 'speed': give one (the spin angle comes from either)")
    time_col = _name(where, "time", raw.get("time", "t"))
    # a probe mapped to the time or pulse column would read the clock as a displacement
    for p in probes:
        for key, column in (("time", time_col), ("keyphasor", kp), ("speed", sp)):
            if column is not None and p.name == column:
                raise RigError(f"{where}: key 'probes.{p.name}': the probe's column is also the {key} column "
                               f"({column!r}); a probe reads its own column")
    return Rig(
        probes=tuple(probes), keyphasor=kp, speed=sp, time=time_col, time_unit=time_unit,
        displacement=disp, sensitivity_mv_per_um=sens, speed_unit=speed_unit,
        keyphasor_threshold=_number(where, "keyphasor_threshold", raw.get("keyphasor_threshold"), allow_none=True),
        planes=planes, model=model, ip=ip, mass_kg=mass,
        slow_roll_rpm=_positive(where, "slow_roll_rpm", raw.get("slow_roll_rpm"), allow_none=True),
        source=where,
    )
