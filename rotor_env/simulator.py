"""Fast fixed-step simulation of the accelerating rotor.

Integrator
----------
Classical RK4 with a fixed sub-step (default ``<= 0.01``), compiled with numba.  The
smooth part of the equations is generated from the effect declarations
(:mod:`rotor_env.effects`): every effect's column function times its coefficients.

Dry friction
------------
The structural-damping moment ``-h v/|v|`` (``v``: velocity of the disk relative to the
rotating shaft) is set-valued at ``v = 0``.  Regularising ``|v| -> sqrt(|v|^2+eps^2)``
with a small ``eps`` (the reference's 1e-6) makes the equations stiff (rate ``h/eps``)
and lets the disk *creep* during the stuck phase; a large ``eps`` changes the answer.
Instead we use the *switch model* (Leine et al., 1998) in a band ``|v| <= eta``:

* stick — if the moment needed to keep ``dv/dt = 0`` is within the friction limit
  ``h`` the friction supplies exactly that moment (``v`` stays put, no creep);
* slip start — otherwise the friction is ``h`` opposing the would-be acceleration.

Outside the band it is the Coulomb law ``-h v/|v|``, whose stiffness ``h/|v|`` is at
most ``h/eta``; ``eta = h * dt_sub / 2`` keeps it inside RK4's stability region.  The
model converges to exact Coulomb friction as ``dt_sub -> 0``; the tests hold it to
``1e-3`` of the peak amplitude against the tight LSODA reference.

Accelerations recorded in the measurements come from the equations of motion at the
recorded state.  Integration is split at parameter jumps (a crack).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from .effects import EFFECTS, Effect
from .measurements import COLUMNS, Measurements
from .params import RotorParams

__all__ = ["RunUp", "SimulationError", "SimulationTooLarge", "Simulator", "simulate"]

MAX_SUBSTEP = 0.01
#: Inclinations above this are treated as a failed (diverged) simulation.
DIVERGENCE_LIMIT = 1e3

STATUS_OK = 0
STATUS_DIVERGED = 1

#: integration steps of one compiled call: between calls Ctrl-C (SIGINT) reaches Python
#: (numba's loops do not look at signals; ~0.3 s of work each)
CHUNK_STEPS = 1_000_000
#: a free-run simulation longer than this many steps is refused (~30 s; a run-up of 40 000
#: samples at dt = 0.01 takes 40 000): the record's time is not in the model's unit
MAX_FREE_RUN_STEPS = 100_000_000
#: a simulation is refused when its samples would take more than this share of the free memory
MEMORY_SHARE = 0.5


class SimulationError(RuntimeError):
    """The simulation diverged (non-finite or huge state)."""


class SimulationTooLarge(ValueError):
    """A simulation that would not fit in memory or would take hours: refused before it starts."""


def _available_memory() -> int:
    """Bytes of memory available now (``MemAvailable``; the physical memory where unknown)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not POSIX
        return 8 << 30


def _size(nbytes: float) -> str:
    for unit in ("bytes", "KB", "MB", "GB", "TB", "PB"):
        if nbytes < 1000 or unit == "PB":
            return f"{nbytes:.3g} {unit}"
        nbytes /= 1000
    raise AssertionError  # pragma: no cover


# ------------------------------------------------------------------ code generation
_ACCEL_CACHE: dict[tuple[str, ...], object] = {}


def smooth_effects(effects: tuple[str, ...]) -> tuple[Effect, ...]:
    return tuple(EFFECTS[e] for e in effects if not EFFECTS[e].dry_friction)


def friction_effect(effects: tuple[str, ...]) -> Effect | None:
    dry = [EFFECTS[e] for e in effects if EFFECTS[e].dry_friction]
    if len(dry) > 1:
        raise ValueError(f"at most one dry-friction effect, got {[e.name for e in dry]}")
    return dry[0] if dry else None


def compile_accel(effects: tuple[str, ...]):
    """A compiled ``accel(phi, phid, phidd, th_x, th_y, w_x, w_y, ip, coef) -> (a_y, a_x)``.

    It sums the gyroscopic terms and every smooth effect's columns times its
    coefficients (``coef``, in declaration order), generated from the declarations.
    Each effect holds :attr:`~rotor_env.effects.Effect.kernel_width` slots of ``coef``:
    its coefficients, then its scanned parameters' values (the rub's clearance), which
    are arguments of its column function — values, not code: one compiled kernel (and
    one cache entry, keyed by the effects) serves every clearance.
    """
    key = tuple(effects)
    if key in _ACCEL_CACHE:
        return _ACCEL_CACHE[key]
    namespace: dict[str, object] = {}
    lines = [
        "def accel(phi, phid, phidd, th_x, th_y, w_x, w_y, ip, coef):",
        "    a_y = -ip * phid * w_x",
        "    a_x = ip * phid * w_y",
    ]
    j = 0
    for i, eff in enumerate(smooth_effects(key)):
        try:
            namespace[f"f{i}"] = njit(inline="always")(eff.columns)
        except Exception as exc:  # pragma: no cover - numba's errors vary
            raise ValueError(f"effect {eff.name!r}: columns cannot be compiled: {exc}") from exc
        nc = len(eff.coefficients)
        # a scanned parameter (the rub's clearance) rides in the coefficient vector after
        # the effect's coefficients and is passed to its column function
        extra = "".join(f", coef[{j + nc + s}]" for s in range(len(eff.argument_parameters)))
        lines.append(f"    cy, cx = f{i}(phi, phid, phidd, th_x, th_y, w_x, w_y, ip{extra})")
        for q in range(nc):
            lines.append(f"    a_y += coef[{j + q}] * cy[{q}]")
            lines.append(f"    a_x += coef[{j + q}] * cx[{q}]")
        j += eff.kernel_width
    lines.append("    return a_y, a_x")
    bound = _file_backed_kernels(key, lines)
    if bound is not None:
        fn = bound.accel
        _BOUND[id(fn)] = bound
    else:
        exec("\n".join(lines), namespace)
        fn = njit(namespace["accel"])
    _ACCEL_CACHE[key] = fn
    return fn


#: id(accel) -> its generated module, whose kernels have ``accel`` as a global (cacheable)
_BOUND: dict[int, object] = {}


def kernel_cache_dir():
    """Where the generated kernels' sources (and so numba's cache of them) live, and other
    results computed once per machine (the change test's simulated null distributions)."""
    from pathlib import Path

    root = os.environ.get("ROTOR_ID_CACHE_DIR")
    if root:
        return Path(root)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "rotor-id"


def _file_backed_kernels(effects: tuple[str, ...], accel_lines: list[str]):
    """The acceleration and the RK4 kernels bound to it, from a generated source file.

    numba cannot cache a function that takes a compiled function as an argument (its cache
    key is that object, new in every process), so every process compiled ``integrate``
    again (2-6 s).  Kernels that hold ``accel`` as a module global have plain signatures:
    written to a file (named by a hash of the source, of this module and of the effects,
    so that an edit never meets a stale cache) they are cached with ``cache=True``.
    Library effects only (a user effect's source may change under the same name); any
    failure (read-only home, no source) returns None: the caller compiles in memory.
    """
    from pathlib import Path

    from . import effects as effects_module

    if os.environ.get("ROTOR_ID_NO_KERNEL_CACHE"):
        return None
    head = ["import math", "", "import numpy as np", "from numba import njit", "",
            "from rotor_env.simulator import _derivs"]
    for i, eff in enumerate(smooth_effects(effects)):
        col = eff.columns
        name = getattr(col, "__name__", "")
        if (getattr(col, "__module__", None) != effects_module.__name__ or getattr(col, "__closure__", None)
                or getattr(effects_module, name, None) is not col):
            return None
        head.append(f"from rotor_env.effects import {name} as _c{i}")
        head.append(f"f{i} = njit(inline='always')(_c{i})")
    body = [
        *head, "", "", "@njit(cache=True)", *accel_lines, "", "",
        # the kernels' own source with accel a global (calling them with accel as an argument
        # would pass a Python object: not cacheable)
        *_bound_source(integrate, "integrate_bound"), "", "",
        *_bound_source(integrate_profile, "integrate_profile_bound"), "", "",
        "@njit(cache=True)",
        "def derivs_bound(tau, thx, thy, wx, wy, phi0, phid0, a, ip, coef, h, eta, My, Mx):",
        "    return _derivs(accel, tau, thx, thy, wx, wy, phi0, phid0, a, ip, coef, h, eta, My, Mx)", "",
    ]
    text = "# generated by rotor_env.simulator.compile_accel; safe to delete\n" + "\n".join(body)
    return load_generated("rotor_id_kernel", text, (Path(__file__), Path(effects_module.__file__)))


def load_generated(prefix: str, text: str, sources: tuple = ()):
    """Import generated kernel source ``text`` from the kernel cache folder (numba's
    ``cache=True`` needs a file): named ``prefix_<hash>`` by a hash of the text, of the
    ``sources`` files it depends on and of the numba and Python versions, so that an edit
    never meets a stale cache.  None on any failure (unwritable folder): compile in memory."""
    import hashlib
    import importlib.util
    import sys
    from pathlib import Path

    try:
        import numba

        digest = hashlib.sha256()
        for part in (text, *(Path(f).read_text() for f in sources), numba.__version__, sys.version):
            digest.update(part.encode())
        name = f"{prefix}_{digest.hexdigest()[:20]}"
        if name in sys.modules:
            return sys.modules[name]
        folder = kernel_cache_dir() / "kernels"
        path = folder / f"{name}.py"
        if not path.exists():
            folder.mkdir(parents=True, exist_ok=True)
            tmp = folder / f".{name}.{os.getpid()}.tmp"
            tmp.write_text(text)
            os.replace(tmp, path)  # atomic: a concurrent process sees all of it or none
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        sys.modules[name] = module
        return module
    except Exception:  # pragma: no cover - unwritable cache folder, odd file systems
        return None


def _bound_source(fn, name: str) -> list[str]:
    """``fn``'s source as ``name``, with its first parameter ``accel`` made a global."""
    import inspect

    lines = inspect.getsource(fn.py_func).splitlines()
    i = next(k for k, line in enumerate(lines) if line.startswith("def "))
    head = f"def {fn.__name__}(accel, "
    if not lines[i].startswith(head):
        raise ValueError(f"{fn.__name__}: unexpected signature")
    body = "\n".join(lines[i + 1:]).replace("integrate(accel, ", "integrate_bound(")
    return ["@njit(cache=True)", f"def {name}(" + lines[i][len(head):], body]


def _integrate(accel, *args):
    """:func:`integrate` from Python, through the cached bound kernel when there is one."""
    bound = _BOUND.get(id(accel))
    return bound.integrate_bound(*args) if bound is not None else integrate(accel, *args)


def call_integrate_profile(accel, *args):
    """:func:`integrate_profile` from Python, through the cached bound kernel when there is
    one (``accel`` from :func:`compile_accel`): no compilation in a second process."""
    bound = _BOUND.get(id(accel))
    return bound.integrate_profile_bound(*args) if bound is not None else integrate_profile(accel, *args)


# ------------------------------------------------------------------------ kernels
@njit(inline="always")
def _derivs(accel, tau, thx, thy, wx, wy, phi0, phid0, a, ip, coef, h, eta, My, Mx):
    phid = phid0 + a * tau
    phi = phi0 + phid0 * tau + 0.5 * a * tau * tau
    ay, ax = accel(phi, phid, a, thx, thy, wx, wy, ip, coef)
    ay += My
    ax += Mx
    if h > 0.0:
        v_y = wy + phid * thx
        v_x = wx - phid * thy
        S = math.sqrt(v_y * v_y + v_x * v_x)
        if S > eta:
            ay -= h * v_y / S
            ax -= h * v_x / S
        else:
            # would-be d v / dt without friction
            g_y = ay + a * thx + phid * wx
            g_x = ax - a * thy - phid * wy
            G = math.sqrt(g_y * g_y + g_x * g_x)
            if G <= h:  # stick: friction holds the relative motion
                ay -= g_y
                ax -= g_x
            else:  # start to slip, friction opposing the would-be motion
                ay -= h * g_y / G
                ax -= h * g_x / G
    return ay, ax


@njit(cache=False)
def integrate(accel, state, t0, phi0, phid0, a, ip, coef, h, My, Mx, n_rec, every, dt_sub, out):
    """Advance ``state = [th_x, th_y, w_x, w_y]`` (in place) by ``n_rec * every`` RK4 steps.

    Spin acceleration ``a`` is constant; the spin starts at ``phi0, phid0`` at ``t0``.
    Records ``n_rec`` rows of the 10 measurement columns into ``out`` after every
    ``every`` sub-steps.  Returns the number of rows written (``< n_rec``: diverged).
    """
    eta = 0.5 * h * dt_sub
    thx, thy, wx, wy = state[0], state[1], state[2], state[3]
    hh = 0.5 * dt_sub
    k6 = dt_sub / 6.0
    # a1 is carried over: the last stage of one step evaluates the new state, which is
    # both the next step's first stage and the recorded acceleration (4 evaluations/step).
    a1y, a1x = _derivs(accel, 0.0, thx, thy, wx, wy, phi0, phid0, a, ip, coef, h, eta, My, Mx)
    step = 0
    for r in range(n_rec):
        for _ in range(every):
            tau = step * dt_sub  # no accumulated rounding in time
            x2, y2, u2, v2 = thx + hh * wx, thy + hh * wy, wx + hh * a1x, wy + hh * a1y
            a2y, a2x = _derivs(accel, tau + hh, x2, y2, u2, v2, phi0, phid0, a, ip, coef, h, eta, My, Mx)
            x3, y3, u3, v3 = thx + hh * u2, thy + hh * v2, wx + hh * a2x, wy + hh * a2y
            a3y, a3x = _derivs(accel, tau + hh, x3, y3, u3, v3, phi0, phid0, a, ip, coef, h, eta, My, Mx)
            x4, y4 = thx + dt_sub * u3, thy + dt_sub * v3
            u4, v4 = wx + dt_sub * a3x, wy + dt_sub * a3y
            a4y, a4x = _derivs(accel, tau + dt_sub, x4, y4, u4, v4, phi0, phid0, a, ip, coef, h, eta, My, Mx)
            thx += k6 * (wx + 2.0 * u2 + 2.0 * u3 + u4)
            thy += k6 * (wy + 2.0 * v2 + 2.0 * v3 + v4)
            wx += k6 * (a1x + 2.0 * a2x + 2.0 * a3x + a4x)
            wy += k6 * (a1y + 2.0 * a2y + 2.0 * a3y + a4y)
            step += 1
            a1y, a1x = _derivs(accel, step * dt_sub, thx, thy, wx, wy, phi0, phid0, a, ip, coef, h, eta, My, Mx)
        if not (abs(thx) < 1e3 and abs(thy) < 1e3 and abs(wx) < 1e6 and abs(wy) < 1e6):
            return r
        tau = step * dt_sub
        out[r, 0] = t0 + tau
        out[r, 1] = phi0 + phid0 * tau + 0.5 * a * tau * tau
        out[r, 2] = phid0 + a * tau
        out[r, 3] = a
        out[r, 4] = thx
        out[r, 5] = thy
        out[r, 6] = wx
        out[r, 7] = wy
        out[r, 8] = a1x
        out[r, 9] = a1y
        state[0], state[1], state[2], state[3] = thx, thy, wx, wy
    return n_rec


# ------------------------------------------------------------------- public API
@dataclass(frozen=True)
class RunUp:
    """A spin profile of constant acceleration ``rate`` from speed ``speed0`` at ``t = 0``."""

    rate: float = 0.01
    speed0: float = 0.0
    phi0: float = 0.0

    def __post_init__(self) -> None:
        for name in ("rate", "speed0", "phi0"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"run-up {name} must be finite, got {getattr(self, name)!r}")


@dataclass
class Simulator:
    """The rotor with given parameters and effects, ready to integrate.

    ``coef`` is the flat coefficient vector of the smooth effects; ``h`` the dry-friction
    limit (0 without the effect).
    """

    params: RotorParams
    max_substep: float = MAX_SUBSTEP
    #: compile the acceleration for these effects (a superset of the rotor's; absent ones
    #: get zero coefficients): one compilation serves every model drawn from the set
    compiled_for: tuple[str, ...] | None = None
    accel: object = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.max_substep) and self.max_substep > 0):
            raise ValueError(f"max_substep must be > 0, got {self.max_substep!r}")
        own = tuple(self.params.effects)
        if self.compiled_for is None:
            layout = own
        else:
            layout = tuple(dict.fromkeys((*self.compiled_for, *own)))
        object.__setattr__(self, "compiled_for", layout)
        self.accel = compile_accel(layout)

    def coefficients(self, t: float | None = None) -> tuple[np.ndarray, float]:
        eff = self.params.effects
        # per effect its coefficients, then its scanned parameters (see compile_accel)
        coef = [c for e in smooth_effects(self.compiled_for)
                for c in ((*self.params.coefficients(e.name, t), *e.scanned_values(self.params.values))
                          if e.name in eff else (0.0,) * e.kernel_width)]
        fr = friction_effect(eff)
        h = self.params.coefficients(fr.name, t)[0] if fr is not None else 0.0
        return np.array(coef, dtype=float), float(h)

    def substeps(self, dt: float) -> tuple[int, float]:
        every = max(1, math.ceil(dt / self.max_substep - 1e-9))
        return every, dt / every

    def run(
        self,
        t_end: float = 400.0,
        dt: float = 0.01,
        run_up: RunUp | float = 0.01,
        initial: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0),
        control: tuple[float, float] = (0.0, 0.0),
        progress: bool = False,
    ) -> Measurements:
        """Simulate ``t`` in ``[0, t_end]``, sampled every ``dt`` (row 0 is ``t = 0``)."""
        if not isinstance(run_up, RunUp):
            run_up = RunUp(rate=float(run_up))
        for name, v in (("t_end", t_end), ("dt", dt)):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number, got {v!r}")
        n_total = round(t_end / dt)
        if n_total < 1:
            raise ValueError(f"t_end={t_end} is shorter than one sample interval dt={dt}")
        every, dt_sub = self.substeps(dt)
        need = (n_total + 1) * len(COLUMNS) * 8.0
        free = _available_memory()
        if need > MEMORY_SHARE * free:
            raise SimulationTooLarge(
                f"t_end={t_end:g} at dt={dt:g} is {n_total + 1:,} samples: they need {_size(need)} of memory "
                f"({len(COLUMNS)} columns of 8 bytes), and {_size(free)} is free; shorten t_end or raise dt"
            )
        state = np.array(initial, dtype=float)
        if state.shape != (4,) or not np.isfinite(state).all():
            raise ValueError(f"initial state must be 4 finite numbers (th_x, th_y, w_x, w_y), got {initial}")
        out = np.empty((n_total + 1, len(COLUMNS)))
        # Split the run at parameter jumps: a crack, and chunks for the progress bar.
        breaks = {n_total}
        crack = self.params.crack
        k_crack = int(round(crack.time / dt)) if crack is not None else None
        if crack is not None and 0 < crack.time < t_end:
            breaks.add(k_crack)
        if progress:  # (not for the lines of a piped command: its file stays bit for bit the same)
            breaks.update(range(0, n_total, max(1, n_total // 100)))
        if n_total * every > CHUNK_STEPS:  # compiled calls of bounded length: Ctrl-C is heard
            breaks.update(range(0, n_total, max(1, CHUNK_STEPS // every)))
        breaks = sorted(b for b in breaks if b > 0)
        pbar = _progress(n_total, enabled=progress)
        a = run_up.rate
        out[0] = self._row(0.0, run_up.phi0, run_up.speed0, a, state, control)
        k = 0
        while k < n_total:
            nxt = next(b for b in breaks if b > k)
            t0 = k * dt
            phi0 = run_up.phi0 + run_up.speed0 * t0 + 0.5 * a * t0 * t0
            phid0 = run_up.speed0 + a * t0
            # from the crack's sample on, D is the cracked one (t0 may fall just before crack.time)
            coef, h = self.coefficients(crack.time if k_crack is not None and k >= k_crack else t0)
            n = nxt - k
            done = _integrate(
                self.accel, state, t0, phi0, phid0, a, self.params.ip, coef, h,
                float(control[1]), float(control[0]), n, every, dt_sub, out[k + 1 : nxt + 1],
            )
            if done < n:
                if pbar is not None:
                    pbar.close()
                raise SimulationError(
                    f"simulation diverged at t = {t0 + (done + 1) * dt:.4g}: |theta| exceeded "
                    f"{DIVERGENCE_LIMIT:g} (unstable parameters?)"
                )
            if pbar is not None:
                pbar.update(n)
            k = nxt
        if pbar is not None:
            pbar.close()
        return Measurements(out)

    def _row(self, t, phi, phid, a, state, control) -> np.ndarray:
        coef, h = self.coefficients(t)
        bound = _BOUND.get(id(self.accel))
        args = (0.0, state[0], state[1], state[2], state[3], phi, phid, a,
                self.params.ip, coef, h, 0.5 * h * self.max_substep, float(control[1]), float(control[0]))
        ay, ax = bound.derivs_bound(*args) if bound is not None else _derivs(self.accel, *args)
        return np.array([t, phi, phid, a, *state, ax, ay])


def _progress(total: int, enabled: bool = True):
    from .progress import bar

    return bar("simulating", total, "samples", enabled=enabled)


def simulate(
    params: RotorParams | Mapping | None = None,
    *,
    t_end: float = 400.0,
    dt: float = 0.01,
    run_up: RunUp | float = 0.01,
    noise: float | Mapping[str, float] | None = None,
    seed: int | None = None,
    progress: bool = False,
    max_substep: float = MAX_SUBSTEP,
) -> Measurements:
    """Simulate a run-up and return the measurements (optionally with sensor noise).

    ``noise`` is the standard deviation of independent Gaussian noise, either one
    number for the six inclination channels (angles, rates, accelerations; the spin
    channels are taken as exact encoder readings) or a mapping channel -> std.
    ``seed`` makes the noise reproducible.
    """
    if params is None:
        params = RotorParams()
    elif not isinstance(params, RotorParams):
        params = RotorParams.from_dict(params)
    meas = Simulator(params, max_substep=max_substep).run(t_end=t_end, dt=dt, run_up=run_up, progress=progress)
    if noise is not None:
        meas = meas.with_noise(noise, seed=seed)
    return meas


@njit(cache=False)
def integrate_profile(accel, state, t, phi, phid, ip, coef, h, every, out):
    """Follow a measured spin profile: constant acceleration between samples.

    The acceleration in interval ``k`` is ``(phid[k+1] - phid[k]) / (t[k+1] - t[k])`` and
    each interval starts from the measured ``phi[k]``, so the simulated spin matches
    the measured one at every sample.  Returns the rows written (``< len(t)``: diverged).
    """
    row = np.empty((1, out.shape[1]))
    for k in range(t.shape[0] - 1):
        dt = t[k + 1] - t[k]
        a = (phid[k + 1] - phid[k]) / dt
        done = integrate(accel, state, t[k], phi[k], phid[k], a, ip, coef, h, 0.0, 0.0, 1, every, dt / every, row)
        if done < 1:
            return k + 1
        for j in range(out.shape[1]):
            out[k + 1, j] = row[0, j]
    return t.shape[0]


def free_run(
    params: RotorParams,
    t: np.ndarray,
    phi: np.ndarray,
    phi_dot: np.ndarray,
    initial: tuple[float, float, float, float],
    max_substep: float = MAX_SUBSTEP,
    compiled_for: tuple[str, ...] | None = None,
) -> Measurements:
    """Simulate ``params`` driven by a measured spin profile from a measured initial state.

    Output error simulation (as MATLAB's ``compare``): nothing from the measured
    inclinations is used after ``t[0]``.  Raises :class:`SimulationError` if the model
    diverges.  ``compiled_for``: see :class:`Simulator` (the diagnosis passes the whole
    library, so that its many candidate models share one compiled kernel).
    """
    sim = Simulator(params, max_substep=max_substep, compiled_for=compiled_for)
    t = np.ascontiguousarray(t, dtype=float)
    if len(t) < 2:
        raise ValueError("free_run needs at least two samples")
    dt = float(np.median(np.diff(t)))
    every, _ = sim.substeps(dt)
    steps = every * (len(t) - 1.0)
    if not steps <= MAX_FREE_RUN_STEPS:
        raise SimulationTooLarge(
            f"the free-run simulation of this record needs {steps:.3g} integration steps ({len(t)} samples "
            f"every {dt:.4g} time units, steps of at most {max_substep:g}), more than the {MAX_FREE_RUN_STEPS:.0e} "
            "allowed: the model's time is dimensionless (natural frequency 1, a run-up samples it every ~0.01); "
            "is 't' in another unit (microseconds, milliseconds)? Rescale it (diagnose does) or decimate the record"
        )
    coef, h = sim.coefficients(float(t[0]))
    state = np.array(initial, dtype=float)
    out = np.empty((len(t), len(COLUMNS)))
    a0 = (phi_dot[1] - phi_dot[0]) / (t[1] - t[0])
    out[0] = sim._row(float(t[0]), float(phi[0]), float(phi_dot[0]), a0, state, (0.0, 0.0))
    phi = np.ascontiguousarray(phi, dtype=float)
    phi_dot = np.ascontiguousarray(phi_dot, dtype=float)
    # in chunks of about CHUNK_STEPS steps: Ctrl-C reaches Python between them (each interval
    # starts afresh from the measured spin, so the chunks give the same numbers as one call)
    per = max(1, CHUNK_STEPS // every)
    done = len(t)
    for k0 in range(0, len(t) - 1, per):
        k1 = min(len(t), k0 + per + 1)
        got = call_integrate_profile(sim.accel, state, t[k0:k1], phi[k0:k1], phi_dot[k0:k1], params.ip, coef, h,
                                     every, out[k0:k1])
        if got < k1 - k0:
            done = k0 + got
            break
    if done < len(t):
        raise SimulationError(f"the model diverged at t = {t[done]:.4g} in the free-run simulation")
    return Measurements(out)
