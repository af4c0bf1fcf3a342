"""The :class:`Simulator`: one soft robot, its state arrays and buffers, stepped by kernels."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from soft_snake_gym.params import SimConfig
from soft_snake_gym.physics import banded, forces, geometry, stepper
from soft_snake_gym.physics import layout as L
from soft_snake_gym.physics.banded import WIDTH, band_to_dense
from soft_snake_gym.physics.cache import drop_stale_cache
from soft_snake_gym.physics.layout import SimArrays, allocate_arrays

__all__ = [
    "SimArrays",
    "Simulator",
    "SimulationError",
    "allocate_arrays",
    "body_from_curvature",
    "node_masses",
    "pack_params",
]

# the cached _simulate embeds stepper.simulate and the kernels it calls from these files
drop_stale_cache(__file__, [m.__file__ for m in (banded, forces, geometry, L, stepper)])

_MEDIA = {"none": L.MEDIUM_NONE, "water": L.MEDIUM_WATER, "ground": L.MEDIUM_GROUND}
_ADDED_MASS = {"consistent": L.ADDED_MASS_CONSISTENT, "kelasidi": L.ADDED_MASS_KELASIDI}
_METHODS = {
    "backward_euler": L.METHOD_BACKWARD_EULER,
    "symplectic_euler": L.METHOD_SYMPLECTIC_EULER,
    "sdirk2": L.METHOD_SDIRK2,
    "bdf2": L.METHOD_BDF2,
}


class SimulationError(RuntimeError):
    """Stepping a simulator whose state has failed (see :attr:`Simulator.failure`)."""


def node_masses(config: SimConfig) -> np.ndarray:
    """Lumped node masses ``m_0 = m/2, m_k = m, m_(N-1) = m/2`` (docs/model.md §3), (N,) [kg]."""
    m = np.full(config.rod.N, config.rod.edge_mass)
    m[0] = m[-1] = 0.5 * config.rod.edge_mass
    return m


def auto_substeps(config: SimConfig) -> int:
    """Sub-steps per ``h``.

    1 for the implicit methods; for the explicit method enough that each is at most ``0.5 / omega_max``
    and ``1 / (damping rate)``, with Gershgorin bounds on the highest elastic frequency and the
    fastest damping rate.
    """
    integ, rod = config.integrator, config.rod
    if integ.substeps is not None:
        return integ.substeps
    if config.method != "symplectic_euler":
        return 1
    l0 = rod.edge_length
    omega_max = 2.0 * math.sqrt((rod.EA / l0 + 16.0 * rod.EI / l0**3) / rod.edge_mass)
    # explicit damping is stable while dt * (damping rate) stays below 2; Gershgorin bound on
    # the rate, as for the stiffness: bending 16 d_b / l0^2 and stretching 4 d_s, per mass
    rate_max = (16.0 * rod.damping_bend / l0**2 + 4.0 * rod.damping_stretch) / rod.edge_mass
    return max(1, math.ceil(integ.h * omega_max / 0.5), math.ceil(integ.h * rate_max / 1.0))


def pack_params(config: SimConfig, prm: np.ndarray) -> None:
    """Write a config into the kernels' parameter vector ``prm`` (``L.N_PRM``,)."""
    rod, fl, gr, it = config.rod, config.fluid, config.ground, config.integrator
    prm[L.P_EA] = rod.EA
    prm[L.P_EI] = rod.EI
    prm[L.P_DBEND] = rod.damping_bend
    prm[L.P_DSTRETCH] = rod.damping_stretch
    prm[L.P_LAG] = rod.length_lag
    prm[L.P_RHO] = fl.rho
    prm[L.P_CF] = fl.C_f
    prm[L.P_CD] = fl.C_D
    prm[L.P_CA] = fl.C_A
    prm[L.P_ADDED_MASS] = _ADDED_MASS[fl.added_mass]
    prm[L.P_A] = rod.a
    prm[L.P_B] = rod.b
    prm[L.P_MUS] = gr.mu_s
    prm[L.P_MUD] = gr.mu_d
    prm[L.P_VTOL] = gr.V_tol
    prm[L.P_G] = gr.g
    prm[L.P_ANISO] = float(gr.anisotropic)
    prm[L.P_MU_FWD], prm[L.P_MU_BWD], prm[L.P_MU_LAT] = gr.kinetic
    prm[L.P_H] = it.h
    prm[L.P_SUBSTEPS] = auto_substeps(config)
    prm[L.P_TOL] = it.newton_tol
    prm[L.P_MAXIT] = it.newton_max_iter
    prm[L.P_CHORD] = it.newton_chord_rate
    prm[L.P_MEDIUM] = _MEDIA[config.medium]
    prm[L.P_METHOD] = _METHODS[config.method]
    prm[L.P_MAXSTRAIN] = it.max_strain
    prm[L.P_CHECKSI] = float(it.check_self_intersection)


def body_from_curvature(
    kbar: np.ndarray,
    lbar: np.ndarray,
    heading: float = 0.0,
    com: tuple[float, float] = (0.0, 0.0),
) -> np.ndarray:
    """Node positions of a body at rest in the shape of a curvature profile.

    Integrates the turning angles ``phi_j = 2 atan(kbar_j / 2)`` along the edges, then turns
    the body so that the tail-to-head chord points along ``heading`` (0: +x, head at node
    N-1 ahead) and moves its centre of mass (lumped masses, uniform edges) to ``com``.

    Args:
        kbar: curvatures of the interior nodes, (N-2,) [-].
        lbar: edge lengths, (N-1,) [m].
        heading: direction of the chord [rad].
        com: centre of mass [m].

    Returns:
        Positions, (N, 2) [m].
    """
    kbar = np.asarray(kbar, dtype=float)
    lbar = np.asarray(lbar, dtype=float)
    if kbar.ndim != 1 or lbar.ndim != 1 or kbar.size != lbar.size - 1:
        raise ValueError(f"kbar has shape {kbar.shape} and lbar {lbar.shape}: need (N-2,) and (N-1,)")
    comx, comy = com
    return _body(kbar, lbar, float(heading), float(comx), float(comy))


@njit(cache=True, error_model="numpy")
def _body(kbar, lbar, heading, comx, comy):
    """:func:`body_from_curvature`'s arithmetic, every sum in node order (each env's reset builds one)."""
    n = lbar.size
    x = np.empty((n + 1, 2))
    theta, cx, cy = 0.0, 0.0, 0.0
    x[0, 0], x[0, 1] = 0.0, 0.0
    for j in range(n):  # the chord, from node 0 at the origin
        if j > 0:
            theta += 2.0 * math.atan(kbar[j - 1] / 2.0)
        cx += lbar[j] * math.cos(theta)
        cy += lbar[j] * math.sin(theta)
        x[j + 1, 0], x[j + 1, 1] = cx, cy
    turn = heading - math.atan2(cy, cx) if math.hypot(cx, cy) > 0 else heading
    c, s = math.cos(turn), math.sin(turn)
    mx, my = 0.0, 0.0
    for i in range(n + 1):
        a, b = x[i, 0], x[i, 1]
        x[i, 0], x[i, 1] = a * c - b * s, a * s + b * c
        w = 0.5 if i == 0 or i == n else 1.0
        mx += w * x[i, 0]
        my += w * x[i, 1]
    mx, my = mx / n, my / n  # the weights sum to n
    for i in range(n + 1):
        x[i, 0] = x[i, 0] - mx + comx
        x[i, 1] = x[i, 1] - my + comy
    return x


@njit(cache=True, error_model="numpy")
def _start_near_rest(f, ibuf, kbar, lbar, u, scale, length_noise, lbar_min, lbar_max):
    """:meth:`Simulator.start_near_rest`'s arithmetic: each draw ``-scale + 2 scale u``, as ``rng.uniform`` makes it.

    The robot is given by its blocks ``f`` and ``ibuf`` (``SimArrays.f``, ``.ibuf``): two arrays for
    numba to unbox instead of a tuple of twenty.
    """
    low, span = -scale, scale - -scale
    nk, nl = kbar.size, lbar.size
    kappa = np.empty(nk)
    for j in range(nk):
        kappa[j] = kbar[j] + (low + span * u[j])
    rest = lbar.copy()
    if length_noise:
        for j in range(nl):
            rest[j] = lbar[j] * (1.0 + (low + span * u[nk + j]))
    x = _body(kappa, rest, low + span * u[u.size - 1], 0.0, 0.0)  # the body of the unclipped lengths
    if length_noise:
        for j in range(nl):
            rest[j] = min(max(rest[j], lbar_min), lbar_max)
    stepper.restart(L.sim_views(f, ibuf), x, np.zeros_like(x), kbar, rest)


@njit(cache=True, error_model="numpy", _nrt=False)
def _simulate(f, ibuf, u_k, u_l, n_steps):
    """``stepper.simulate`` of the robot over its blocks ``f`` and ``ibuf`` (:meth:`Simulator.advance`).

    Its views are made as the envs' kernels make theirs (``layout.sim_views``), so one compiled
    ``simulate`` serves both: called with the plain tuple, numba compiled it a second time (about
    8 s on a cold cache).
    """
    return stepper.simulate(L.sim_views(f, ibuf), u_k, u_l, n_steps)


def _as_array(name: str, value, shape: tuple[int, ...]) -> np.ndarray:
    """``value`` as a C-contiguous float64 array of ``shape``, finite (the kernels' and ``start``'s inputs)."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != shape:
        raise ValueError(f"{name} has shape {arr.shape}; expected {shape}")
    if not np.isfinite(arr).all():
        bad = np.flatnonzero(~np.isfinite(arr.ravel()))
        raise ValueError(f"{name} has non-finite entries at flat indices {bad.tolist()[:8]}")
    return np.ascontiguousarray(arr)


class Simulator:
    """A planar discrete elastic rod in water, on the ground, or in vacuum (docs/model.md).

    The simulator allocates its arrays once; :meth:`reset` and :meth:`set_state` write into
    them, :meth:`set_config` changes physical parameters in place (for per-episode
    randomization) without rebuilding anything. Steps run entirely in numba kernels.

    State (read as copies): ``x``, ``v`` (N, 2) [m, m/s], ``kbar`` (N-2,) [-], ``lbar`` (N-1,)
    [m]. Inputs to :meth:`step`: curvature rates ``u_k`` (N-2,) [1/s] and length rates ``u_l``
    (N-1,) [m/s], held over the step ``h``.

    A step that fails (Newton not converged, non-finite state, self-intersection, runaway
    stretch, a non-positive rest length) sets :attr:`failure` to the reason; stepping again
    raises :class:`SimulationError` until :meth:`reset` or :meth:`set_state`.

    Example:
        >>> sim = Simulator()
        >>> sim.step(u_k=np.full(sim.N - 2, 0.1))
        >>> sim.kappa.round(4)[:2]
        array([0.001, 0.001])
    """

    def __init__(self, config: SimConfig | None = None, *, arrays: SimArrays | None = None) -> None:
        """Build the simulator for ``config`` (default ``SimConfig()``), in ``arrays`` if given."""
        config = SimConfig() if config is None else config
        if not isinstance(config, SimConfig):
            raise TypeError(f"config must be a SimConfig, got {type(config).__name__}")
        self.N = N = config.rod.N
        if arrays is None:
            arrays = allocate_arrays(N)
        elif not isinstance(arrays, SimArrays) or arrays.q.shape != (2 * N,):
            got = (
                f"SimArrays with q of shape {arrays.q.shape}"
                if isinstance(arrays, SimArrays)
                else type(arrays).__name__
            )
            raise ValueError(
                f"arrays is {got}: need the SimArrays of one robot of N = {N} nodes, q of shape "
                f"({2 * N},) (allocate_arrays({N}), or .row(i) of a batch's)"
            )
        self.arrays = arrays
        """The kernels' arrays (:class:`~soft_snake_gym.physics.layout.SimArrays`): the state
        ``q``, ``v`` (2N,), ``kbar``, ``lbar``, parameters, scratch and diagnostics ``out``.
        Views of a batch's stacked arrays when the simulator is one robot of a batch. Read them
        freely; write only through the simulator's methods."""
        self._zero_k = np.zeros(N - 2)
        self._zero_l = np.zeros(N - 1)
        self.failure: str | None = None
        self.set_config(config)
        self.reset()

    # --- configuration and state ---------------------------------------------------------
    def set_config(self, config: SimConfig) -> None:
        """Change the physical and numerical parameters in place (same N)."""
        if config.rod.N != self.N:
            raise ValueError(
                f"config.rod.N = {config.rod.N} differs from this simulator's N = {self.N}; "
                "build a new Simulator to change the number of nodes"
            )
        self.config = config
        pack_params(config, self.arrays.prm)
        self._m = node_masses(config)
        self.arrays.buf[L.B_M, 0::2] = self._m
        self.arrays.buf[L.B_M, 1::2] = self._m
        self.arrays.buf[L.B_MINV] = 1.0 / self.arrays.buf[L.B_M]

    @property
    def h(self) -> float:
        """Step [s]."""
        return self.config.integrator.h

    @property
    def substeps(self) -> int:
        """Internal sub-steps per step."""
        return int(self.arrays.prm[L.P_SUBSTEPS])

    def reset(self, x=None, v=None, kbar=None, lbar=None) -> None:
        """Start over.

        By default a straight body at rest along +x, centre of mass at the origin, rest shape
        straight with the configured edge length; clears accumulated energies, time and any failure.
        """
        x, v, kbar, lbar, _ = self._checked(x, v, kbar, lbar)
        N = self.N
        kbar = np.zeros(N - 2) if kbar is None else kbar
        lbar = np.full(N - 1, self.config.rod.edge_length) if lbar is None else lbar
        x = body_from_curvature(kbar, lbar) if x is None else x
        self.start(x, np.zeros((N, 2)) if v is None else v, kbar, lbar)

    def start(self, x: np.ndarray, v: np.ndarray, kbar: np.ndarray, lbar: np.ndarray) -> None:
        """:meth:`reset` to a whole state its caller built and checked, in one compiled call.

        ``x``, ``v`` (N, 2), ``kbar`` (N-2,), ``lbar`` (N-1,): C-contiguous float64, finite, every
        rest and node-to-node length positive, as the envs' reset bodies are. Nothing is checked
        here; :meth:`reset` checks what it is given, then calls this.
        """
        stepper.restart(tuple(self.arrays), x, v, kbar, lbar)
        self.failure = None

    def start_near_rest(
        self,
        kbar: np.ndarray,
        lbar: np.ndarray,
        rng: np.random.Generator,
        scale: float,
        lbar_limits: tuple[float, float] | None = None,
    ) -> None:
        """:meth:`start` at rest near the rest shape ``kbar`` (N-2,), ``lbar`` (N-1,), drawn from ``rng``.

        The body is bent to the curvatures ``kbar + U(-scale, scale)`` along the edges ``lbar``, or,
        with ``lbar_limits``, along ``lbar (1 + U(-scale, scale))``, which the rest lengths then take,
        clipped to ``lbar_limits``; its chord points along ``U(-scale, scale)`` [rad], its centre of
        mass at the origin. The draws are ``rng.uniform(-scale, scale, ...)``'s numbers, in that
        order (one ``rng.random`` call), and the body :func:`body_from_curvature`'s, in one compiled
        call. ``kbar`` and ``lbar``: C-contiguous float64, as :meth:`start` takes them.
        """
        length_noise = lbar_limits is not None
        lo, hi = lbar_limits if length_noise else (0.0, 0.0)
        draws = rng.random(kbar.size + (lbar.size if length_noise else 0) + 1)
        a = self.arrays
        _start_near_rest(a.f, a.ibuf, kbar, lbar, draws, float(scale), length_noise, lo, hi)
        self.failure = None

    def set_state(self, x=None, v=None, kbar=None, lbar=None, lbar_dot=None) -> None:
        """Overwrite any part of the state; the others are kept. Clears a failure.

        ``lbar_dot`` (N-1,) [m/s] sets the length actuators' rates (the state of their lag).
        """
        x, v, kbar, lbar, lbar_dot = self._checked(x, v, kbar, lbar, lbar_dot)
        if x is not None:
            self.arrays.q[:] = x.ravel()
        if v is not None:
            self.arrays.v[:] = v.ravel()
        if kbar is not None:
            self.arrays.kbar[:] = kbar
        if lbar is not None:
            self.arrays.lbar[:] = lbar
        if lbar_dot is not None:
            self.arrays.buf[L.B_LRATE, : self.N - 1] = lbar_dot
        self.failure = None
        stepper.start_from_state(tuple(self.arrays))  # contacts, predictor, history, energy ledger

    def _checked(self, x, v, kbar, lbar, lbar_dot=None) -> tuple[np.ndarray | None, ...]:
        """The given parts of a state as float64 arrays of their shapes, finite; None stays None.

        Raises ``ValueError`` for a wrong shape, a non-finite entry, a non-positive rest length
        or two successive nodes at the same place.
        """
        N = self.N
        x = None if x is None else _as_array("x", x, (N, 2))
        v = None if v is None else _as_array("v", v, (N, 2))
        kbar = None if kbar is None else _as_array("kbar", kbar, (N - 2,))
        lbar = None if lbar is None else _as_array("lbar", lbar, (N - 1,))
        lbar_dot = None if lbar_dot is None else _as_array("lbar_dot", lbar_dot, (N - 1,))
        if lbar is not None and (lbar <= 0).any():
            raise ValueError(f"lbar must be positive, got min {lbar.min()!r}")
        if x is not None:
            lengths = np.hypot(*(x[1:] - x[:-1]).T)
            if (lengths <= 0).any():
                raise ValueError(
                    f"x puts nodes {np.flatnonzero(lengths <= 0).tolist()} on top of their "
                    "successors: every edge needs a positive length"
                )
        return x, v, kbar, lbar, lbar_dot

    def set_external_force(self, force=None) -> None:
        """Apply a constant external force to each node, (N, 2) [N]; ``None`` removes it."""
        if force is None:
            self.arrays.buf[L.B_FEXT] = 0.0
        else:
            self.arrays.buf[L.B_FEXT] = _as_array("force", force, (self.N, 2)).ravel()

    # --- stepping ------------------------------------------------------------------------
    def _inputs(self, u_k, u_l) -> tuple[np.ndarray, np.ndarray]:
        if u_k is None:
            uk = self._zero_k
        elif isinstance(u_k, np.ndarray) and u_k.shape == (self.N - 2,) and u_k.dtype == np.float64:
            uk = u_k
        else:
            uk = _as_array("u_k", u_k, (self.N - 2,))
        if u_l is None:
            ul = self._zero_l
        elif isinstance(u_l, np.ndarray) and u_l.shape == (self.N - 1,) and u_l.dtype == np.float64:
            ul = u_l
        else:
            ul = _as_array("u_l", u_l, (self.N - 1,))
        if not (np.isfinite(uk.sum()) and np.isfinite(ul.sum())):
            _as_array("u_k", uk, uk.shape)
            _as_array("u_l", ul, ul.shape)
        return uk, ul

    def step(self, u_k=None, u_l=None) -> bool:
        """Advance by ``h`` with curvature and length rates held constant; True if the step succeeded.

        Curvature rates ``u_k`` (N-2,) and length rates ``u_l`` (N-1,) (``None``: zero). On failure
        :attr:`failure` names the reason.
        """
        return self.advance(1, u_k, u_l)

    def advance(self, n_steps: int, u_k=None, u_l=None) -> bool:
        """Advance by ``n_steps`` steps in one compiled call (inputs constant throughout)."""
        if self.failure is not None:
            raise SimulationError(
                f"the simulation failed ({self.failure}) at t = {self.time:.3f} s; "
                "call reset() or set_state() before stepping again"
            )
        uk, ul = self._inputs(u_k, u_l)
        status = _simulate(self.arrays.f, self.arrays.ibuf, uk, ul, n_steps)
        if status != L.OK:
            self.failure = L.STATUS_REASONS[status]
            return False
        return True

    # --- observables ---------------------------------------------------------------------
    @property
    def x(self) -> np.ndarray:
        """Node positions, (N, 2) [m] (a copy)."""
        return self.arrays.q.reshape(self.N, 2).copy()

    @property
    def v(self) -> np.ndarray:
        """Node velocities, (N, 2) [m/s] (a copy)."""
        return self.arrays.v.reshape(self.N, 2).copy()

    @property
    def kbar(self) -> np.ndarray:
        """Rest curvatures, (N-2,) [-] (a copy)."""
        return self.arrays.kbar.copy()

    @property
    def lbar(self) -> np.ndarray:
        """Rest lengths, (N-1,) [m] (a copy)."""
        return self.arrays.lbar.copy()

    @property
    def lbar_dot(self) -> np.ndarray:
        """Rates of the rest lengths, (N-1,) [m/s] (a copy).

        The inputs ``u_l`` seen through the length actuators' lag ``Rod.length_lag`` (equal to
        the last inputs without lag).
        """
        return self.arrays.buf[L.B_LRATE, : self.N - 1].copy()

    @property
    def kappa(self) -> np.ndarray:
        """Curvatures ``2 tan(phi/2)`` of the interior nodes, (N-2,) [-]."""
        out = np.empty(self.N - 2)
        geometry.curvatures(self.arrays.q, out)
        return out

    @property
    def kappa_dot(self) -> np.ndarray:
        """Exact curvature rates (docs/model.md §2), (N-2,) [1/s]."""
        out = np.empty(self.N - 2)
        geometry.curvature_rates(self.arrays.q, self.arrays.v, out)
        return out

    @property
    def edge_lengths(self) -> np.ndarray:
        """Current edge lengths ``|e^k|``, (N-1,) [m]."""
        out = np.empty(self.N - 1)
        geometry.edge_lengths(self.arrays.q, out)
        return out

    @property
    def edge_length_rates(self) -> np.ndarray:
        """Rates of the edge lengths, (N-1,) [m/s]."""
        out = np.empty(self.N - 1)
        geometry.edge_length_rates(self.arrays.q, self.arrays.v, out)
        return out

    @property
    def com(self) -> np.ndarray:
        """Centre of mass, (2,) [m]."""
        return self._m @ self.arrays.q.reshape(self.N, 2) / self._m.sum()

    @property
    def com_velocity(self) -> np.ndarray:
        """Velocity of the centre of mass, (2,) [m/s]."""
        return self._m @ self.arrays.v.reshape(self.N, 2) / self._m.sum()

    @property
    def heading(self) -> float:
        """Direction of the tail-to-head chord ``x[N-1] - x[0]`` [rad]."""
        q = self.arrays.q
        return math.atan2(q[-1] - q[1], q[-2] - q[0])

    @property
    def masses(self) -> np.ndarray:
        """Lumped node masses, (N,) [kg]."""
        return self._m.copy()

    @property
    def stuck(self) -> np.ndarray:
        """Which nodes stuck to the ground in the last step, (N,) bool (all False off ground)."""
        if self.config.medium != "ground":
            return np.zeros(self.N, dtype=bool)
        return self.arrays.ibuf[L.I_FRICTION, : self.N] == L.STUCK

    def elastic_energy(self) -> float:
        """Stretching plus bending energy [J]."""
        a = self.arrays
        geo = np.empty((2, a.q.size))
        geometry.edge_geometry(a.q, geo)
        return float(forces.elastic_energy(geo, a.kbar, a.lbar, a.prm))

    def kinetic_energy(self) -> float:
        """Kinetic energy of the nodes (not of the entrained water) [J]."""
        return float(0.5 * self.arrays.buf[L.B_M] @ (self.arrays.v * self.arrays.v))

    def fluid_kinetic_energy(self) -> float:
        """Kinetic energy of the water moved with the body, ``T_f = sum_i 1/2 mu_n (v^i .

        n^i)^2`` (docs/model.md §4; 0 out of water) [J].
        """
        if self.config.medium != "water":
            return 0.0
        a = self.arrays
        return float(forces.fluid_kinetic_energy(a.q, a.v, a.prm))

    def energy_ledger(self) -> dict[str, float]:
        """The energy balance since the last :meth:`reset` or :meth:`set_state` (docs/model.md §4).

        ``actuator_work = fluid_dissipation + damping_dissipation + friction_dissipation +
        delta_kinetic + delta_elastic + delta_fluid_kinetic + error``, all in J.

        ``delta_*`` are the changes of the body's kinetic energy, its elastic energy and the
        water's kinetic energy ``T_f``. ``error`` is the work that the integrator destroyed (> 0,
        e.g. backward Euler's numerical damping) or created (< 0); it shrinks with the step for
        the consistent added mass, as ``h`` under backward Euler and as ``h^2`` under SDIRK2.
        Work of :meth:`set_external_force` forces is not counted (it shows up in ``error``).
        """
        return L.energy_ledger(self.arrays.out.tolist())

    def elastic_forces(self) -> np.ndarray:
        """Elastic plus damping forces on the nodes, (N, 2) [N]."""
        F = np.zeros(2 * self.N)
        a = self.arrays
        forces.assemble(
            a.q, a.v, a.kbar, a.lbar, a.prm, F, a.J, 0.0, 0.0, False, False, a.buf[L.B_GEO : L.B_GEO + 2]
        )
        return F.reshape(self.N, 2)

    def force_jacobians(self, water: bool | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Forces and their analytic Jacobians ``dF/dx`` and ``dF/dv`` as dense (2N, 2N) matrices.

        In interleaved (x0, y0, x1, ...) order: elastic, damping and (in water) drag. For checking
        and analysis; the stepper uses the banded form.
        """
        water = self.config.medium == "water" if water is None else water
        a = self.arrays
        n = 2 * self.N
        F = np.zeros(n)
        mats = []
        for cx, cv in ((1.0, 0.0), (0.0, 1.0)):
            F[:] = 0.0
            J = np.zeros((n, WIDTH))
            forces.assemble(
                a.q, a.v, a.kbar, a.lbar, a.prm, F, J, cx, cv, True, water, a.buf[L.B_GEO : L.B_GEO + 2]
            )
            mats.append(band_to_dense(J, n))
        return F.copy(), mats[0], mats[1]

    # --- metrics of the last step and accumulated ------------------------------------------
    @property
    def time(self) -> float:
        """Simulated time since the last reset [s] (steps times h, so it does not drift)."""
        return float(self.arrays.out[L.O_NSTEPS] * self.h)

    @property
    def newton_iterations(self) -> int:
        """Newton iterations of the last step (0 for the explicit integrator)."""
        return int(self.arrays.out[L.O_NITER])

    @property
    def newton_work(self) -> dict[str, int]:
        """What Newton did in the last step, summed over its stages and sub-steps (0s if explicit).

        ``jacobians``: Jacobian assemblies, each with its residual; ``residuals``: residuals
        alone (line-search trials and chord steps); ``factorizations``: banded factorizations.
        """
        out = self.arrays.out
        return {
            "jacobians": int(out[L.O_NJAC]),
            "residuals": int(out[L.O_NRES]),
            "factorizations": int(out[L.O_NFACTOR]),
        }

    @property
    def fluid_power(self) -> float:
        """Power lost to drag over the last step, ``-sum F_D . v >= 0`` [W]."""
        return float(self.arrays.out[L.O_P_FLUID])

    @property
    def friction_power(self) -> float:
        """Power lost to ground friction over the last step [W]."""
        return float(self.arrays.out[L.O_P_FRICTION])

    @property
    def actuator_power(self) -> float:
        """Power of the inputs on the body over the last step (signed) [W]."""
        return float(self.arrays.out[L.O_P_ACT])

    @property
    def fluid_energy(self) -> float:
        """Energy lost to drag since reset [J]."""
        return float(self.arrays.out[L.O_E_FLUID])

    @property
    def friction_work(self) -> float:
        """Work done against friction since reset [J]."""
        return float(self.arrays.out[L.O_E_FRICTION])

    @property
    def actuator_energy(self) -> float:
        """Actuator energy since reset, the sum over steps of |work| [J].

        A real actuator does not get back the work the body does on it.
        """
        return float(self.arrays.out[L.O_E_ACT])

    @property
    def damping_power(self) -> float:
        """Power lost to material damping over the last step [W].

        ``damping_bend sum kappa_dot^2 + damping_stretch sum ldot^2``.
        """
        return float(self.arrays.out[L.O_P_DAMP])

    @property
    def damping_energy(self) -> float:
        """Energy lost to material damping since reset [J]."""
        return float(self.arrays.out[L.O_E_DAMP])

    @property
    def actuator_work(self) -> float:
        """Signed actuator work since reset [J]."""
        return float(self.arrays.out[L.O_W_ACT])
