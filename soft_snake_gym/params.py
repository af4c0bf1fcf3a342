"""Physical and numerical parameters, as frozen and validated dataclasses (docs/model.md §9).

Every field is in SI units and named as in docs/model.md. Impossible values raise ``ValueError``
naming the field, the value and the allowed range, so a typo in a YAML file or a sweep grid
fails at construction time instead of as a NaN a thousand steps later.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import InitVar, dataclass, fields
from typing import Any, Literal

__all__ = [
    "Rod",
    "Fluid",
    "Ground",
    "Integrator",
    "SimConfig",
    "Medium",
    "check_int",
    "check_number",
    "plain_number",
]

Medium = Literal["water", "ground", "none"]


def plain_number(value: Any, integer: bool = False) -> int | float | None:
    """``value`` as a Python ``int`` or ``float`` if it is a real number, else None.

    Real numbers include numpy scalars such as ``np.int64`` and ``np.float32``. Booleans are not
    numbers. With ``integer``, only integers (Python or numpy) qualify.

    Frozen configs keep the Python number, so they stay hashable and YAML-dumpable.
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return None
    if isinstance(value, numbers.Integral):
        return int(value)
    return None if integer else float(value)


def check_number(
    where: str,
    value: Any,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    hi_open: bool = False,
) -> int | float:
    """The one validator of a real number.

    ``value`` as a Python number if it is a finite number within [lo, hi] (open ends with
    ``lo_open``/``hi_open``; ``None``: unbounded), else ``ValueError`` naming ``where`` (e.g.
    ``"Rod.E"``), the value and the allowed range.
    """
    left = "(" if lo_open or lo is None else "["
    right = ")" if hi_open or hi is None else "]"
    allowed = f"{left}{'-inf' if lo is None else lo}, {'inf' if hi is None else hi}{right}"
    number = plain_number(value)
    if number is None:
        raise ValueError(f"{where} = {value!r} must be a number in {allowed}")
    if not math.isfinite(number):
        raise ValueError(f"{where} = {value!r} must be a finite number in {allowed}")
    bad = False
    if lo is not None:
        bad |= number <= lo if lo_open else number < lo
    if hi is not None:
        bad |= number >= hi if hi_open else number > hi
    if bad:
        raise ValueError(f"{where} = {value!r} is outside the allowed range {allowed}")
    return number


def _check(
    owner: object,
    name: str,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    hi_open: bool = False,
) -> None:
    """:func:`check_number` on the field ``owner.name``; a numpy scalar becomes a Python number."""
    value = getattr(owner, name)
    number = check_number(f"{type(owner).__name__}.{name}", value, lo, hi, lo_open, hi_open)
    if type(number) is not type(value):  # a numpy scalar: keep the Python number
        object.__setattr__(owner, name, number)


def check_int(where: str, value: Any, lo: int, hi: int | None = None, hint: str = "") -> int:
    """:func:`check_number` for integers.

    ``value`` as a Python ``int`` if it is an integer (Python or numpy, not a bool) in [lo, hi],
    else ``ValueError`` naming ``where``, the value, the allowed range and, if given, ``hint`` (what
    the number means or what else is allowed).
    """
    number = plain_number(value, integer=True)
    if number is None or number < lo or (hi is not None and number > hi):
        allowed = f"[{lo}, {'inf' if hi is None else hi}]"
        raise ValueError(
            f"{where} = {value!r} must be an integer in {allowed}" + (f" ({hint})" if hint else "")
        )
    return number


def _check_int(owner: object, name: str, lo: int, hi: int | None = None) -> None:
    """:func:`check_int` on the field ``owner.name``; a numpy integer becomes a Python int."""
    value = getattr(owner, name)
    number = check_int(f"{type(owner).__name__}.{name}", value, lo, hi)
    if type(number) is not type(value):  # a numpy integer: keep the Python int
        object.__setattr__(owner, name, number)


#: the longest length-actuator lag ``Rod.length_lag`` takes [s]
LENGTH_LAG_MAX = 10.0


@dataclass(frozen=True)
class Rod:
    """The soft body: N nodes, N-1 edges of elliptic cross-section (docs/model.md §3, §9).

    ``N`` alone adds or removes edges of the same length and mass: ``Rod(N=300)`` is a 54 m
    eel. To model the *same* robot (length, mass, cross-section, material) with more nodes,
    refine it: ``Rod().refined(40)``, or the key ``refine`` (``rod={"refine": 40}`` in an env
    or a YAML file), which applies to the robot the other keys describe. Refining to N nodes
    keeps the length ``L`` and mass ``M``: ``edge_length = L/(N-1)``, ``edge_mass = M/(N-1)``;
    it scales both dampings by ``l_old/l_new`` (like ``EI/lvor`` and ``EA/l``, so that the
    dissipation per unit length of a given body motion does not depend on N), and it records
    in ``refined_from`` the node count of the robot as designed, on which the gaits' per-node
    amplitude and phase offset are given (``soft_snake_gym.gaits.serpenoid_on_nodes`` maps
    them onto arc length; the envs scale their per-node action bounds by ``edge_ratio``).

    Attributes:
        N: number of nodes (>= 3); the head is node N-1. More nodes add edges of the same
            ``edge_length`` and ``edge_mass``: a longer, heavier robot, not a finer model of
            the same one (N = 300 is a 53.8 m body).
        edge_length: rest length of every edge at rest, ``lbar`` at t = 0 [m].
        edge_mass: mass of every edge [kg]; node masses are lumped from it.
        a: half-height of the cross-section, out of the plane [m].
        b: half-width of the cross-section, in the plane [m].
        E: Young's modulus [Pa], used for both stiffnesses unless overridden.
        E_stretch: stretching modulus [Pa] overriding ``E`` in ``EA`` (None: use ``E``).
        E_bend: bending modulus [Pa] overriding ``E`` in ``EI`` (None: use ``E``).
        damping_bend: Kelvin-Voigt damping of bending: a generalized force
            ``-damping_bend * kappa_dot`` at each interior node [N m s] (docs/model.md §3). Default
            1.0: the smallest tried (0, 0.5, 0.75, 1) at which the PID's closed loop, the open
            loop and the shipped eel give the same metrics with the step divided by 4 and 16
            (at 0.5 the PID's fluid power still moved 5.7 %); a loss factor of about 1 % at the
            thesis gait, 0.8 of critical for the zig-zag mode. The sources use 0 (``preset="thesis"``).
        damping_stretch: Kelvin-Voigt damping of stretching: a force ``-damping_stretch`` times
            the stretch rate along each edge [N s/m] (docs/model.md §3). Default 0: no baseline
            needs it to converge.
        length_lag: time constant of the length actuators [s]: the rest-length rates follow the
            commanded ``u_l`` with a first-order lag, ``tau d(lbar_dot)/dt = u_l - lbar_dot``
            (integrated exactly over each step; docs/model.md §3). Default 0.05: a rate that
            jumps at once rings the stretching mode (950 rad/s) on the ground, which a 0.01 s
            step cannot resolve; with 0.05 s random actions on the worm give the same friction
            energy within 7.5 % at h, h/4 and h/16 (0.04 s: 9.6 %, 0.03 s: 12.9 %, against the
            ground's 10 %). 0 (at most 10): the rates jump (the sources' setting,
            ``preset="thesis"``). The curvature inputs ``u_k`` act at once.
        refined_from: node count of the robot this rod refines (the robot as designed, whose
            per-node gait parameters apply); None: the rod is not a refinement.
        damping: removed; passing it raises an error naming ``damping_bend`` and
            ``damping_stretch``, which replace it.
        refine: construction only: build the same robot with this many nodes (>= 3), as
            described above; the stored fields are those of the refined rod.
    """

    N: int = 10
    edge_length: float = 0.18
    edge_mass: float = 0.8
    a: float = 0.055
    b: float = 0.05
    E: float = 1.875e6
    E_stretch: float | None = None
    E_bend: float | None = None
    damping_bend: float = 1.0
    damping_stretch: float = 0.0
    length_lag: float = 0.05
    refined_from: int | None = None
    damping: InitVar[float | None] = None
    refine: InitVar[int | None] = None

    def __post_init__(self, damping: float | None, refine: int | None) -> None:
        """Check the values, reject the removed ``damping`` and apply ``refine``."""
        if damping is not None:
            raise ValueError(
                f"Rod.damping = {damping!r} is no longer a parameter: it was split into "
                "damping_bend [N m s] (on curvature rates) and damping_stretch [N s/m] (on "
                "stretch rates); use those instead"
            )
        _check_int(self, "N", 3, 100_000)
        _check(self, "edge_length", 0.0, None, lo_open=True)
        _check(self, "edge_mass", 0.0, None, lo_open=True)
        _check(self, "a", 0.0, None, lo_open=True)
        _check(self, "b", 0.0, None, lo_open=True)
        _check(self, "E", 0.0, None, lo_open=True)
        if self.E_stretch is not None:
            _check(self, "E_stretch", 0.0, None, lo_open=True)
        if self.E_bend is not None:
            _check(self, "E_bend", 0.0, None, lo_open=True)
        _check(self, "damping_bend", 0.0, None)
        _check(self, "damping_stretch", 0.0, None)
        _check(self, "length_lag", 0.0, LENGTH_LAG_MAX)
        if self.refined_from is not None:
            _check_int(self, "refined_from", 3, 100_000)
        if refine is not None:
            if isinstance(refine, bool) or not isinstance(refine, int) or not 3 <= refine <= 100_000:
                raise ValueError(
                    f"Rod.refine = {refine!r} must be an integer in [3, 100000]: the number of "
                    "nodes of the same robot (same length and mass) to build"
                )
            factor = (self.N - 1) / (refine - 1)  # l_new / l_old
            design = self.N if self.refined_from is None else self.refined_from
            for name, value in (
                ("N", refine),
                ("edge_length", self.edge_length * factor),
                ("edge_mass", self.edge_mass * factor),
                ("damping_bend", self.damping_bend / factor),
                ("damping_stretch", self.damping_stretch / factor),
                ("refined_from", None if design == refine else design),
            ):
                object.__setattr__(self, name, value)

    def refined(self, N: int) -> Rod:  # noqa: N803 - docs/model.md's name
        """The same robot (length, mass, cross-section, material) with ``N`` nodes; see the class docstring.

        ``Rod().refined(10) == Rod()``.
        """
        return dataclasses.replace(self, refine=N)

    @property
    def design_nodes(self) -> int:
        """Node count of the robot as designed: ``refined_from``, or N if not refined."""
        return self.N if self.refined_from is None else self.refined_from

    @property
    def edge_ratio(self) -> float:
        """``l / l_design``.

        This rod's edge length over that of the robot as designed (exactly 1.0 for a rod that is not
        a refinement) [-].
        """
        return (self.design_nodes - 1) / (self.N - 1)

    @property
    def area(self) -> float:
        """Cross-section area ``A = pi a b`` [m^2]."""
        return math.pi * self.a * self.b

    @property
    def second_moment(self) -> float:
        """In-plane second moment of area ``I = pi a b^3 / 4`` [m^4]."""
        return math.pi * self.a * self.b**3 / 4.0

    @property
    def EA(self) -> float:  # noqa: N802 - docs/model.md's name
        """Stretching stiffness [N]."""
        return (self.E if self.E_stretch is None else self.E_stretch) * self.area

    @property
    def EI(self) -> float:  # noqa: N802 - docs/model.md's name
        """Bending stiffness [N m^2]."""
        return (self.E if self.E_bend is None else self.E_bend) * self.second_moment

    @property
    def length(self) -> float:
        """Rest length of the whole body [m]."""
        return (self.N - 1) * self.edge_length

    @property
    def total_mass(self) -> float:
        """Mass of the whole body [kg]."""
        return (self.N - 1) * self.edge_mass


@dataclass(frozen=True)
class Fluid:
    """Water at rest, Morison-type drag and normal added mass (docs/model.md §4).

    Attributes:
        rho: density of the water [kg/m^3].
        C_f: tangential (skin friction) drag coefficient [-], on the edge's surface.
        C_D: normal drag coefficient [-], on the edge's projected area.
        C_A: normal added-mass coefficient [-], times the water displaced by the edge.
        added_mass: ``"consistent"`` (default): the Lagrangian force of the water's kinetic
            energy ``T_f``, which exchanges energy with the body without creating any;
            ``"kelasidi"``: the sources' acceleration term alone, which does net work on
            rotating edges.
    """

    rho: float = 1000.0
    C_f: float = 0.3
    C_D: float = 1.75
    C_A: float = 1.5
    added_mass: Literal["consistent", "kelasidi"] = "consistent"

    def __post_init__(self) -> None:
        """Check ``added_mass`` and the values."""
        if self.added_mass not in ("consistent", "kelasidi"):
            raise ValueError(
                f"Fluid.added_mass = {self.added_mass!r} is unknown; use 'consistent' "
                "(energy-conserving, the default) or 'kelasidi' (the sources' form)"
            )
        _check(self, "rho", 0.0, None)
        _check(self, "C_f", 0.0, None)
        _check(self, "C_D", 0.0, None)
        _check(self, "C_A", 0.0, None)


@dataclass(frozen=True)
class Ground:
    """Stick-slip Coulomb friction on a flat floor, decided at the end of each step (docs/model.md §5).

    A node ends a step at rest where the force needed to hold it is within ``mu_s F_N``
    (``F_N = m_i g``) and otherwise slides with kinetic friction against its end velocity.

    Attributes:
        mu_s: static friction coefficient [-]: a node ends a step at rest while the force
            needed to hold it is at most ``mu_s m g``.
        mu_d: kinetic (dynamic) friction coefficient [-], ``0 <= mu_d <= mu_s``: a sliding node
            feels ``mu_d m g`` against its velocity.
        V_tol: a node that ends a step slower than this sticks [m/s].
        g: gravitational acceleration [m/s^2].
        mu_forward: anisotropic option: kinetic coefficient for sliding toward the head along
            the body's local tangent [-]; ``None`` (default): ``mu_d``.
        mu_backward: the same for sliding toward the tail [-]; ``None``: ``mu_d``.
        mu_lateral: the same across the body [-]; ``None``: ``mu_d``. The three set, friction
            is ``-F_N (mu_t v_t t + mu_lateral v_n n) / |v|``, with ``mu_t`` the forward or
            backward coefficient by the sign of ``v_t`` (as setae and snake scales give).
            Each must be at most ``mu_s``; the static threshold stays ``mu_s``.
    """

    mu_s: float = 1.15
    mu_d: float = 0.8
    V_tol: float = 1e-3
    g: float = 9.81
    mu_forward: float | None = None
    mu_backward: float | None = None
    mu_lateral: float | None = None

    def __post_init__(self) -> None:
        """Check the values (``mu_d <= mu_s`` among them)."""
        _check(self, "mu_s", 0.0, None)
        _check(self, "mu_d", 0.0, None)
        _check(self, "V_tol", 0.0, None, lo_open=True)
        _check(self, "g", 0.0, None)
        if self.mu_d > self.mu_s:
            raise ValueError(
                f"Ground.mu_d = {self.mu_d!r} exceeds Ground.mu_s = {self.mu_s!r}: kinetic "
                "friction must not exceed static friction (allowed: 0 <= mu_d <= mu_s)"
            )
        for name in ("mu_forward", "mu_backward", "mu_lateral"):
            if getattr(self, name) is not None:
                _check(self, name, 0.0, self.mu_s)

    @property
    def anisotropic(self) -> bool:
        """True if any directional coefficient differs from ``mu_d``."""
        return any(c is not None and c != self.mu_d for c in self.kinetic)

    @property
    def kinetic(self) -> tuple[float, float, float]:
        """(forward, backward, lateral) kinetic coefficients, ``mu_d`` where not set."""
        return tuple(
            self.mu_d if c is None else c for c in (self.mu_forward, self.mu_backward, self.mu_lateral)
        )


METHODS = ("auto", "backward_euler", "sdirk2", "bdf2", "symplectic_euler")


@dataclass(frozen=True)
class Integrator:
    """Time integration (docs/model.md §5a).

    Attributes:
        method: ``"auto"`` (default): ``"sdirk2"`` in water and out of any medium,
            ``"backward_euler"`` on the ground. ``"sdirk2"``: two backward-Euler stages per step
            (second order, L-stable; not on the ground, where friction is decided at the end of
            one implicit step). ``"bdf2"``: one backward-Euler stage per step from the last two
            steps (second order, L-stable, about 1.4 times cheaper than SDIRK2 under random
            actions, with more numerical damping; not on the ground; a fresh state's first step
            is SDIRK2's). ``"backward_euler"``: one implicit step, first order. All by Newton on
            the banded analytic Jacobian. ``"symplectic_euler"``: explicit, sub-stepped; needs
            ``Rod.damping_bend > 0`` under the curvature PID. See docs/model.md §5a.
        h: step [s]; the inputs are held constant over it.
        substeps: internal steps per ``h``; ``None`` picks 1 for the implicit methods and, for the
            explicit method, enough that each sub-step is at most 0.5 / omega_max, with
            omega_max the rod's highest stretching frequency.
        newton_tol: tolerance of a Newton step on the momentum residual divided by the node
            masses, max-norm [m/s].
        newton_max_iter: iteration cap; a step that does not converge is reported as a failure.
        newton_chord_rate: modified Newton off the ground: after an iteration that shrank the
            residual by at least this factor, the next one reuses its Jacobian's factorization (a
            chord step: one solve and one residual) instead of a new Jacobian; the tolerance is
            the same, so only the rounding of the converged step changes. 0 turns reuse off.
        max_strain: a step with ``| |e|/lbar - 1 |`` above this is reported as runaway stretch.
        check_self_intersection: test the body for crossing edges after every step.
    """

    method: Literal["auto", "backward_euler", "sdirk2", "bdf2", "symplectic_euler"] = "auto"
    h: float = 0.01
    substeps: int | None = None
    newton_tol: float = 1e-6
    newton_max_iter: int = 30
    newton_chord_rate: float = 0.1
    max_strain: float = 0.5
    check_self_intersection: bool = True

    def __post_init__(self) -> None:
        """Check ``method`` and the values."""
        if self.method not in METHODS:
            raise ValueError(
                f"Integrator.method = {self.method!r} is unknown; use one of {', '.join(map(repr, METHODS))}"
            )
        _check(self, "h", 0.0, 1.0, lo_open=True)
        if self.substeps is not None:
            _check_int(self, "substeps", 1, 1_000_000)
        _check(self, "newton_tol", 0.0, None, lo_open=True)
        _check_int(self, "newton_max_iter", 1, 10_000)
        _check(self, "newton_chord_rate", 0.0, 1.0, hi_open=True)
        _check(self, "max_strain", 0.0, None, lo_open=True)
        if not isinstance(self.check_self_intersection, bool):
            raise ValueError(
                f"Integrator.check_self_intersection = {self.check_self_intersection!r} must be true or false"
            )


@dataclass(frozen=True)
class SimConfig:
    """Everything a :class:`~soft_snake_gym.physics.Simulator` needs.

    ``medium`` selects which of ``fluid`` and ``ground`` acts; the other is kept so that one
    YAML file can describe the robot in both settings.
    """

    rod: Rod = Rod()
    medium: Medium = "water"
    fluid: Fluid = Fluid()
    ground: Ground = Ground()
    integrator: Integrator = Integrator()

    def __post_init__(self) -> None:
        """Check ``medium`` and the types of the sections."""
        if self.medium not in ("water", "ground", "none"):
            raise ValueError(
                f"SimConfig.medium = {self.medium!r} is unknown; use 'water', 'ground' or 'none'"
            )
        for f in fields(self):
            value = getattr(self, f.name)
            expected = {"rod": Rod, "fluid": Fluid, "ground": Ground, "integrator": Integrator}
            if f.name in expected and not isinstance(value, expected[f.name]):
                raise ValueError(
                    f"SimConfig.{f.name} must be a {expected[f.name].__name__}, got {type(value).__name__}"
                )
        if self.medium == "ground" and self.integrator.method in ("sdirk2", "bdf2"):
            raise ValueError(
                f"SimConfig: integrator.method = {self.integrator.method!r} does not run on the ground, where friction "
                "is decided at the end of one backward-Euler step (docs/model.md §5); use "
                "'backward_euler' or 'auto'"
            )

    @property
    def method(self) -> str:
        """The integration method in use: ``integrator.method`` with ``"auto"`` resolved by medium."""
        if self.integrator.method != "auto":
            return self.integrator.method
        return "backward_euler" if self.medium == "ground" else "sdirk2"
