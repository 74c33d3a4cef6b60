"""The default semismooth Newton method: the paper's steps where they work, an interior-point phase elsewhere.

The paper's semismooth Newton method [semi_newton] converges Q-quadratically near a solution, but it is a local
method: from ordinary starts a zero multiplier meeting an active bound, a cost that is linear in a player's own
variables, or dependent constraint gradients make JPhi singular, and far from a solution a full step can
overshoot. This method keeps the local method's steps and adds what it lacks, after PATH's design (a Newton step
first, judged by a nonmonotone watchdog; a more robust method when it fails; restarts when that stalls):

0. **The affine VI's solution** (LQ games whose KKT system is an affine variational inequality: Nash problems,
   variational GNEs, and plain GNEs whose shared rows every player involved carries; :mod:`gnerun.solvers.avi`).
   The first step is the Josephy-Newton step [eq:JN], which for an affine game is the exact solution, by DAQP's
   active-set AVI solver in C (PATH's design: a pivotal method on the linearisation). One iteration; the Newton
   phase goes on from there, or from z^0 where DAQP finds no solution (an LQ plain GNE without a variational
   equilibrium, FK A.8).
   **A start outside the costs' domain** (Phi(z^0) not finite: log(x) or x log(x) at a bound x = 0, as start values of
   0 on such bounds give): the decisions pushed ``PUSH`` into their bounds, as IPOPT's bound_push does, else each
   bounded one at its box's centre, else the design point of least finite ||Phi|| over the boxes; that is z^0 (the
   local method stops at the configured start instead).
   **The players' decoupled plans** (nonlinear trajectory games of several players with rows that couple them,
   cold-started and unperturbed, where ||Phi(z^0)|| > ``DECOUPLE_ABOVE``): the first iteration is the players' plans as
   if each were alone, the equilibrium of the decoupled game (the rows that two or more players' decisions reach,
   collision rows and shared resources, left out: ``KKTSystem.without_rows``), solved by this method itself from z^0 to
   ||Phi|| <= ``ALONE_TOL`` (its interior phase first; at most ``ALONE_STEPS`` iterations, on the game's own compiled
   system: nothing is built per player), multipliers zero. It is taken as the new z^0 where ||Phi|| there is at most
   ``DECOUPLED_GAIN`` times ||Phi(z^0)||. Where a later iterate's ||Phi|| exceeds the configured z^0's, or the first
   interior start from the new z^0 fails, the configured z^0 takes that iterate's place and the solve goes on from it as
   it would have (the overtaking game's cars planned alone drive through each other). From the plans the interior
   phase begins at once (``PLANS_INTERIOR``: the Newton step from them, which leaves the coupling rows' multipliers at
   zero, climbed on every merge measured). On ALGAMES's merges the plans
   alone are near the equilibrium (||Phi|| 60-110 times lower than at zero inputs): the median solve takes 12 iterations
   instead of 18, the p90 14 instead of 33 (19 and 22 counting the decoupled solve's own 8), the slowest 23 instead of
   71; the intersections' start plans are near stationary already (||Phi(z^0)|| < 1) and are left alone (measured:
   benchmarks/results/solver-design.md). The decoupled game's solve and the interior phase from its plans take a
   faster barrier (``interior_point.KAPPA_PLANS``: counted through the decoupled solve, the merges' median 15 instead
   of 19), and there ``FAST_STALL`` steps without progress, not ``STALL``, give the solve back to the configured
   z^0 (where the faster barrier stalls: the overtaking game from "car 1 brakes").
   **A start near stationary** (such a game whose ||Phi(z^0)|| is at most ``QUICK_BELOW``, cold-started and
   unperturbed): its first interior start takes the faster barrier too; ``FAST_STALL`` stalled steps there begin the
   same start again at the usual pace. ALGAMES's intersections from zero inputs: median 9 iterations instead of 14.5
   (the overtaking game's three starts near stationary: 4-6 more, 28-50). Where that start is the configured start
   values, the interior phase begins at once (``QUICK_INTERIOR``: the Newton step from there climbed on every such
   start measured); a start handed to the solver keeps its Newton step first (a guess near a solution).
1. **Newton phase.** The semismooth Newton step (min map or Fischer-Burmeister, with the configured perturbation)
   is taken unless it multiplies ||Phi|| by more than ``BLOWUP`` over a nonmonotone reference (the largest of its
   last ``MEMORY`` values), as PATH's watchdog does: the local method's own path may climb before it converges.
   ``WATCHDOG`` steps without a new best value (``SUFFICIENT`` below the best), a non-finite Phi or a refused
   step end the phase. Where JPhi is singular, the Levenberg-Marquardt step is taken instead (a proximal
   perturbation of the singular matrix, mu = ``LM_FAR`` ||Phi||). In a nonlinear game (unperturbed), the first step
   from z^0 may not raise ||Phi|| more than ``FIRST_STEP``-fold, nor a later min-map step of that phase (before any
   interior phase) more than ``LATER_STEP``-fold: the linearisation there is then no guide, and the interior phase
   takes this iteration instead of the watchdog's climb (on an LQ game the min-map
   Newton steps are an exact active-set search whose climbs lead to the solution: FK A.7; a closed loop's warm
   start keeps its Newton step too, see ``_climbs_first``). On the paper's games this takes exactly the paper's
   steps.
2. **Interior phase** (:mod:`gnerun.solvers.interior_point`), from the start: interior-point steps, well defined
   at singular and degenerate points, that also reach a point of a non-isolated solution set (plain GNEs whose
   shared constraints several players carry). While ||Phi|| is above ``RESET_ABOVE`` times the hand-over threshold,
   each step is followed by the slack reset (:meth:`~gnerun.solvers.interior_point.InteriorPoint.reset_slacks`:
   rows guessed inactive whose constraint lies further inside than the slack says); near a solution the slack's
   lag is of second order in the step and the reset only perturbs the steps (on ALGAMES's merges and
   intersections it then makes some of them cycle). If ||Phi|| makes no new best for ``STALL`` steps, or a step cannot
   be computed, the phase restarts from the start with the next starting point of the interior-point method;
   after ``RESTARTS`` restarts the solve ends with the status of what went wrong.
3. **Hand-over.** Once ||Phi|| at an interior iterate is below a threshold, the Newton step is tried from it
   (where JPhi is singular there, as on a continuum of solutions, the Levenberg-Marquardt step with mu = ||Phi||,
   which converges to a point of the set under an error bound); when it reduces ||Phi|| at least
   ``HANDOVER_DECREASE``-fold, the Newton phase resumes (and with it Q-quadratic convergence at a regular
   solution), keeping the interior iterate to return to. Where it does not, the step is tried again (up to
   ``HANDOVER_ROUNDS`` times) on the active set the step itself points to, as a primal-dual active-set method
   corrects its guess: rows whose multiplier came out negative leave it, rows the step violates join it. An
   interior iterate's guess (lambda_j > w_j) is wrong for the rows that are inactive at the solution with a slack
   below sqrt(eps), and these make the plain step climb far (||Phi|| times 80-380 on ALGAMES's merges). A refused
   hand-over is tried again once ||Phi|| is below ``HANDOVER_RETRY`` times its value there. A later Newton step of
   the resumed phase that multiplies ||Phi|| by more than ``CORRECT_ABOVE`` is corrected in the same way (a row
   whose multiplier the step drives negative, another it leaves violated); where no correction halves ||Phi||, the
   climbing step is the watchdog's to judge, as before.
4. **Pivoting** (LQ games only). When every interior start has failed, the KKT system, a linear complementarity
   problem, is solved by Lemke's method from z^0 (covering vectors: all ones, then seeded random ones). The
   central path of the interior phase gives the copies of a shared constraint equal multipliers, so it misses
   plain GNEs that have no variational counterpart (FK A.8); complementary pivoting does not.
5. **A line-search phase** (unperturbed runs of the condensed formulation; not for games with abs, min or max of
   the decisions, which the smoothing homotopy of :mod:`gnerun.runs.smoothing` takes after a failed solve). An
   interior phase still running after ``SLOW`` iterations of the solve hands z^0 to semismooth Newton on the
   Fischer-Burmeister function with Armijo backtracking on 1/2||Phi_FB||^2 (the method of ``globalization:
   line_search`` with ``complementarity: fischer_burmeister``), once per solve, for at most ``SEARCH_STEPS``
   iterations; once ||Phi|| is below the hand-over threshold the Newton phase takes over as from an interior
   iterate. Where the search does not converge (no step length decreases the merit, a singular JPhi, the budget)
   the interior phase goes on from the iterate it had reached. On games whose barrier path is long (formation games
   of several robots with pairwise clearance) the search converges in a fraction of the iterations, or at all;
   measured in benchmarks/results/solver-design.md.
6. **Rounds of best responses** (nonlinear games of several players; at most two per solve). When the first
   interior start from z^0 stalls, each player's best answer to the others' plans where it stalled
   (:mod:`gnerun.solvers.response_round`) is the new start, and the interior phase begins again from it, with the
   small barrier of a warm start and then its other starting points. Where no player has a feasible answer to
   those plans, the other starts from z^0 follow. When every start has failed, the answers to the others' plans
   of the configured start are the new start, in the same way. The interior phase stalls where no equilibrium is
   near (on ALGAMES's merges: a car pressed between another car and the ramp, the Newton direction driving one
   row's slack and multiplier to zero by turns); the plans it reached there mostly avoid each other, so the
   players have answers, and the answers are a start from which the joint problem converges. Cold-started
   trajectory games (the overtaking game of the robustness suite) stall from z^0 and converge from there.

One call of ``step`` is one iteration: one accepted step (a Newton step tried and refused costs an extra
evaluation inside it). The iterate z = (a, lambda) and ||Phi|| are the semismooth Newton method's in every phase,
so logs, tolerances and closed loops read the same.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from . import interior_point
from .avi import AffineVI
from .design import kronecker
from .driver import iterate
from .interior_point import STARTS, InteriorIterate, InteriorPoint
from .josephy_newton import kkt_lcp_point
from .linalg import largest, norm
from .line_search_newton import LineSearchNewton
from .response_round import response_round
from .ssn import SemismoothNewton
from .status import FAILURES, SSNState, Status, evolve

MEMORY = 4  # nonmonotone reference: the largest ||Phi|| of this many last accepted Newton iterates
WATCHDOG = 4  # Newton steps without a new best ||Phi|| (SUFFICIENT below it) before the interior phase takes over
BLOWUP = 1e3  # a Newton step that multiplies the nonmonotone reference by more than this is refused at once
SUFFICIENT = 0.1  # progress: ||Phi|| at least this fraction below the best so far
HANDOVER_AT = 1e-2  # try the Newton step from an interior iterate once ||Phi|| <= this x min(||Phi(z^0)||, 1)
HANDOVER_DECREASE = 0.5  # ... and take it when it reduces ||Phi|| at least by this factor
HANDOVER_RETRY = 0.5  # after a refused hand-over, the next try once ||Phi|| is below this fraction of where it was
HANDOVER_ROUNDS = 3  # a refused hand-over step is tried again this many times with its active set corrected
CORRECT_ABOVE = 30.0  # ... and so is a Newton step after a hand-over that multiplies ||Phi|| by more than this
STALL = 15  # interior steps without a new best ||Phi|| (by 10%) before a restart (or a round of best responses)
FAST_STALL = 3  # ... at the faster barrier (from the decoupled plans, or a first start near stationary): then the
# configured z^0 again, at the usual pace (a faster barrier that stalls does so within a few steps)
RESTARTS = len(STARTS) - 1
LM_FAR = 1e-4  # far from a solution, a singular JPhi gets the Levenberg-Marquardt step with mu = LM_FAR ||Phi||
FLAT = 1e-2  # a Levenberg-Marquardt step that changes ||Phi|| by less than this fraction ends the Newton phase
PIVOTS = 8  # LQ games: Lemke's method from this many covering vectors after the interior phase's restarts
SLOW = 60  # iterations without convergence, in the interior phase, after which the line-search phase is tried (once)
SEARCH_STEPS = 30  # the line-search phase's budget of iterations
RESET_ABOVE = 3.0  # the interior phase resets its slacks while ||Phi|| is above this times the hand-over threshold
# nonlinear games: the first Newton step from z^0 is refused if it multiplies ||Phi|| by more than FIRST_STEP; the
# merges' and intersections' first steps climb 1.85-72-fold, FK A.1 from 0.01's 1.2-fold and the local method goes on
# to converge from there in 9 steps, cheaper than the interior phase's 5 (the default's time 2.8 times the local one's
# at 1.0)
FIRST_STEP = 1.5
# ... and a later min-map step of that phase if it multiplies ||Phi|| by more than LATER_STEP: a merge whose first step
# climbed 1.48-fold climbed 7.4-fold at its second and then took 17 Levenberg-Marquardt steps of 4.5 ms each (31
# iterations, 13 with the rule); formation starts whose later steps climb 2-4-fold converge from there (draw 26 of
# seed 1: 10 iterations, 71 with the rule at 1.5)
LATER_STEP = 5.0
# a Newton step whose iterate is finite, at most halves ||Phi|| and moves z by at most max(||z||_inf, 1) in any entry
# is kept without the condition estimate of a nonlinear game's sparse matrix (it costs 110 us against the banded
# factorisation's 150 on the 41-knot merge): a matrix ill-conditioned enough to be refused makes steps far longer (an
# error of about eps / rcond in relative terms) or no better, and the interior phase takes its steps on their results
# alone
TAKEN_DECREASE = 0.5


def _taken(state: SSNState, new: SSNState) -> bool:
    """Whether the Newton step from ``state`` to ``new`` is kept on its result alone (TAKEN_DECREASE)."""
    if new.status != Status.RUNNING or not new.residual_norm <= TAKEN_DECREASE * state.residual_norm:
        return False
    return _short(state.z, new.z)


def _short(z: np.ndarray, z_new: np.ndarray) -> bool:
    """Whether the step from z to z_new moves no entry by more than max(||z||_inf, 1) (see TAKEN_DECREASE)."""
    return largest(z_new - z) <= max(largest(z), 1.0)


# a cold-started trajectory game whose ||Phi(z^0)|| is above this begins with the players' decoupled plans, kept where
# ||Phi|| there is at most DECOUPLED_GAIN times ||Phi(z^0)|| (benchmarks/results/solver-design.md)
PUSH = 1e-2  # a start outside the costs' domain: its decisions pushed this far into their bounds (IPOPT's bound_push)
DOMAIN_DESIGN = 32  # ... else the best of this many design points over the boxes where Phi is finite
DECOUPLE_ABOVE = 1.0
DECOUPLED_GAIN = 0.1
# ... a cold-started trajectory game whose ||Phi(z^0)|| is at most this (near stationary, as ALGAMES's intersections
# from zero inputs, 0.35-0.5) takes the faster barrier in its first interior start instead
QUICK_BELOW = 1.0
ALONE_TOL = 1e-3  # ... to this ||Phi|| of the decoupled game: a start, not a solution (its last Newton steps spared)
ALONE_STEPS = 50  # the decoupled game's solve: at most this many iterations (unconverged: no decoupled plans)
# ... and from the plans the interior phase at once, without a Newton step first: the plans leave the coupling rows
# out (their multipliers zero, the rows violated or slack), and the min-map step from there climbed and was refused on
# 200 of 200 of ALGAMES's merges and the overtaking start kept its plans for, at the cost of a factorisation, a
# condition estimate and an evaluation (0.37 ms of a merge's solve) (False: the Newton step is tried first)
PLANS_INTERIOR = True
# ... and so from a start near stationary (QUICK_BELOW) that is the configured start values (zero multipliers): from the
# intersections' zero inputs the Newton step climbed and was refused on every start measured (the robustness suite's
# 10 intersections and 3 overtaking starts, the 20 of the iteration benchmark), at the cost of a factorisation, its
# estimate and two evaluations (0.5-0.7 ms, 10-14% of an intersection's solve). A start handed to the solver (a guess
# near a solution, its multipliers zero or not) keeps its Newton step: from the intersections' solutions moved by
# 1e-2 it converges in 3-4 iterations, the interior phase in 6-39 (False: the Newton step is tried first)
QUICK_INTERIOR = True


@dataclass(slots=True, frozen=True, kw_only=True)
class Memory:
    """What the method keeps between steps (in ``SSNState.search``)."""

    phase: str  # "newton" | "interior" | "search"
    merits: tuple[float, ...]  # ||Phi|| of the last accepted Newton iterates (the nonmonotone reference)
    best: float  # the best ||Phi|| of the current phase
    stalls: int  # steps of the current phase since its best
    interior: InteriorIterate | None  # the interior iterate (interior phase), or the one to return to
    handover: float  # try the Newton step from the interior phase once ||Phi|| <= this
    origin: np.ndarray  # z^0, where restarts begin
    handover0: float  # the first hand-over threshold (restarts begin with it)
    attempt: int = 0  # interior-phase starts so far
    crash: bool = False  # the first step is still to be the affine VI's solution (LQ games, gnerun.solvers.avi)
    answered: bool = False  # z^0 is the players' best answers (gnerun.solvers.response_round) ...
    cold: int = 0  # ... first taken after this many starts from the configured z^0 ...
    before: int = 0  # ... and this z^0's starts came after this many others
    answered_start: bool = False  # the answers to the configured start's plans have been taken
    start: np.ndarray | None = None  # the configured z^0, once z^0 is the answers
    searched: bool = False  # the line-search phase has been tried
    inner: SSNState | None = None  # the line-search phase's own state (its Phi is the Fischer-Burmeister one)
    steps: int = 0  # iterations of the line-search phase so far
    warm: bool = False  # z^0 is a closed loop's warm start (the first-step rule does not apply)
    decouple: bool = False  # the first step is to be the players' decoupled plans (HybridNewton._decoupled)
    abandon: float = math.inf  # ||Phi|| at the configured z^0, while z^0 is the decoupled plans: above it, back there
    alone: int = 0  # the iterations of the decoupled game's solve inside the first iteration (0: none)
    quick: bool = False  # the first interior start from z^0 is to take the faster barrier (a start near stationary)
    leap: bool = False  # the first step is the interior phase's start, without a Newton step before it (from the
    # decoupled plans: PLANS_INTERIOR; from the configured start values near stationary: QUICK_INTERIOR)
    fast: bool = False  # this interior start takes the faster barrier (HybridNewton._kappa)


class HybridNewton:
    """Semismooth Newton with an interior-point phase (see the module docstring). ``newton`` is the paper's
    method on the configured formulation (condensed or sparse); its init, terminate and finish are used as
    they are."""

    def __init__(self, newton: SemismoothNewton, *, handover: bool = True, polish: float = 0.0) -> None:
        self.newton = newton
        self.game = newton.game
        self.options = newton.options
        self.interior = InteriorPoint(newton)
        self.handover = handover  # False: the interior phase alone (solver.globalization: interior_point)
        # the interior phase alone, polished: Newton steps once ||Phi|| <= polish where every player's block of the
        # barrier matrix needs no convexifying shift (second-order sufficiency: a minimum, not a saddle the interior
        # phase would leave), each kept only where it reduces ||Phi|| (the certificate's local solves: the barrier's
        # last decades in a step or two)
        self.polish = 0.0 if handover else polish
        # LQ games whose KKT system is an affine VI: the first step solves it (unperturbed runs only: a perturbed
        # method is run to be studied step by step)
        d = newton.disturbance
        exact = d.kind == "none" or d.scale == 0
        self.avi = AffineVI.of(self.game) if handover and exact and newton.condensed else None
        # games of several players: a round of best responses after every interior start has failed (not for LQ
        # games, which pivot instead; whether the game is LQ is asked only then)
        self.answers = handover and len(self.game.agent_names) > 1
        # cold-started trajectory games of several players whose rows couple them: the players' decoupled plans first
        self.decouples = (self.answers and exact and bool(self.game.horizon)
                          and bool(self.game.pattern.joint_rows.any()))
        # ... and where the start is near stationary instead, the faster barrier in the first interior start
        self.quickens = self.answers and exact and bool(self.game.horizon)
        # the line-search phase: the condensed formulation's Newton method on the Fischer-Burmeister function, built
        # on first use (the sparse formulation takes min-map steps alone; a perturbed method is studied as it is)
        self.searches = handover and exact and newton.condensed
        self.exact = exact
        self.plans = False  # the decoupled game's own solve (:attr:`_alone`): the faster barrier (:meth:`_kappa`)
        # the rows a hand-over's active set may hold: inequalities that a decision reaches
        self._inequalities = np.zeros(self.game.m, dtype=bool)
        self._inequalities[self.interior.I] = True

    def forget(self) -> None:
        """Drop the Newton method's factorisations kept per active set."""
        self.newton.forget()

    @property
    def polisher(self) -> SemismoothNewton:
        """The method whose iterations polish a solution (the reference solution z*): the plain Newton steps."""
        return self.newton

    def at_solution(self, state: SSNState) -> bool:
        return self.newton.at_solution(state)

    # the step-wise interface (STYLE.md) ----------------------------------------------------
    def init(self, z0: np.ndarray | None = None, x: np.ndarray | None = None,
             rng: np.random.Generator | None = None, warm: bool = False) -> SSNState:
        state = self.newton.init(z0, x, rng)
        if state.status == Status.NAN and not warm:
            state = self._inside(state, x, rng)
        if state.status in FAILURES:
            return state
        merit = state.residual_norm
        decouple = self.decouples and not warm and merit > DECOUPLE_ABOVE  # (NaN: not)
        quick = self.quickens and not warm and merit <= QUICK_BELOW
        leap = quick and QUICK_INTERIOR and np.array_equal(state.z, self.game.z_start())
        state.search = self._from(state, crash=self.avi is not None, warm=warm, decouple=decouple,
                                  quick=quick, leap=leap)  # a new state
        if not self.handover:  # the interior phase alone: its start point is z^0
            return self._start_interior(state, 0, k=0)
        return state

    def _inside(self, state: SSNState, x: np.ndarray | None, rng: np.random.Generator | None) -> SSNState:
        """A start whose Phi is not finite (log(x) or x log(x) at a bound x = 0, the configured start): its decisions
        pushed into their bounds as IPOPT's bound_push does (``PUSH`` of the bound's size, at most ``PUSH`` of the
        box's width), else each bounded on both sides at its box's centre, the first of these where Phi is finite;
        else, of ``DOMAIN_DESIGN`` points of a Kronecker design over those boxes, the one of least finite ||Phi||; or
        the state as it was."""
        game, n = self.game, self.game.n
        lo, hi, a = game.a_lower, game.a_upper, state.z[:n]
        with np.errstate(invalid="ignore"):  # (inf - inf where a decision has no bounds: no push, no centre)
            room = np.where(np.isfinite(hi - lo), PUSH * (hi - lo), np.inf)
            pushed = np.maximum(a, lo + np.minimum(PUSH * np.maximum(1.0, np.abs(lo)), room))
            pushed = np.minimum(pushed, hi - np.minimum(PUSH * np.maximum(1.0, np.abs(hi)), room))
            centre = np.where(np.isfinite(lo) & np.isfinite(hi), 0.5 * (lo + hi), a)
        for start in (pushed, centre):
            if np.array_equal(start, a) or not np.all(np.isfinite(start)):
                continue
            moved = self.newton.init(np.concatenate([start, state.z[n:]]), x, rng)
            if moved.status not in FAILURES:
                return moved
        # a design over the decisions' boxes (those without both bounds at their start): the one of least ||Phi||
        box = np.isfinite(lo) & np.isfinite(hi)
        if not box.any():
            return state
        best = state  # its ||Phi|| is NaN: the first finite one is taken, then any lower
        for u in kronecker(int(box.sum()), DOMAIN_DESIGN, np.random.default_rng(0)):
            start = a.copy()
            start[box] = lo[box] + (hi[box] - lo[box]) * u
            moved = self.newton.init(np.concatenate([start, state.z[n:]]), x, rng)
            if moved.status not in FAILURES and not moved.residual_norm >= best.residual_norm:
                best = moved
        return best

    def restart(self, z0: np.ndarray, x: np.ndarray | None = None,
                rng: np.random.Generator | None = None) -> SSNState:
        """``init`` for a start near an equilibrium (a KKT point at which some agents moved to their best
        responses, as :func:`~gnerun.runs.solving.certified_solve` restarts): the interior phase at once, with
        the small barrier of a warm start (``interior_point.WARM``); a Newton step from there, with its zero
        multipliers, is rarely accepted (measured: benchmarks/results/solver-design.md)."""
        state = self.init(z0, x, rng)
        if state.status in FAILURES or not self.handover:
            return state
        return self._start_interior(state, 0, k=0, warm=True)

    def terminate(self, state: SSNState) -> tuple[bool, Status]:
        return self.newton.terminate(state)

    def finish(self, state: SSNState) -> SSNState:
        return self.newton.finish(state)

    def step(self, state: SSNState) -> SSNState:
        """Exactly one iteration (see the module docstring); a failed or converged state is returned unchanged (a
        step at a solution keeps it: no phase change, no interior restart)."""
        if state.status in FAILURES or self.newton.at_solution(state):
            return state
        memory: Memory = state.search
        if memory.phase == "newton":
            new = self._newton_step(state, memory)
        elif memory.phase == "search":
            new = self._search_step(state, memory)
        else:
            new = self._interior_step(state, memory)
        after = new.search
        if after is not None and new.residual_norm > after.abandon and new.status not in FAILURES:
            return self._abandoned(new, after)  # (NaN: not above; the checks of the phases decide)
        return new

    # -------------------------------------------------------------------------------------
    def _threshold(self, merit0: float) -> float:
        """||Phi|| below which the Newton step is tried from an interior iterate."""
        if not self.handover:
            return self.polish if self.polish > 0.0 else -1.0
        return HANDOVER_AT * min(merit0, 1.0) if math.isfinite(merit0) else HANDOVER_AT

    def _candidate(self, state: SSNState, memory: Memory) -> tuple[SSNState, bool]:
        """The Newton step from ``state``; where JPhi is singular, the Levenberg-Marquardt step instead (a
        proximal perturbation of the singular matrix: mu = ||Phi|| close to a solution, LM_FAR ||Phi|| far).
        The flag says which was taken (True: Levenberg-Marquardt)."""
        candidate = self.newton.iteration(state, taken=_taken)  # (hybrid.step has returned at a solution)
        if candidate.status != Status.SINGULAR_JACOBIAN:
            return candidate, False
        near = state.residual_norm <= memory.handover
        if not (near or LM_FAR):
            return candidate, False
        z = self.newton.regularized_point(state, state.residual_norm * (1.0 if near else LM_FAR))
        return (candidate, False) if z is None else (self.newton.advance(state, z, rcond=candidate.rcond), True)

    def _crash(self, state: SSNState, memory: Memory) -> SSNState | None:
        """The affine VI's solution as the first iterate (:mod:`gnerun.solvers.avi`), if DAQP finds one that
        reduces ||Phi||; None otherwise (the Newton step is taken instead)."""
        z = self.avi.point(self.game.lq.offsets(state.x), state.z.size)
        if z is None:
            return None
        candidate = self.newton.advance(state, z)
        merit = candidate.residual_norm
        if candidate.status != Status.RUNNING or not merit < state.residual_norm:
            return None
        candidate.search = Memory(phase="newton", merits=(*memory.merits[-MEMORY + 1:], merit), best=merit, stalls=0,
                                  interior=None, handover=memory.handover, origin=memory.origin,
                                  handover0=memory.handover0)
        return candidate

    def _decoupled(self, state: SSNState, memory: Memory) -> SSNState | None:
        """The players' decoupled plans (the decoupled game's equilibrium from z^0, :attr:`_alone`; multipliers zero)
        as the first iterate and the new z^0, where that solve converges within ``ALONE_STEPS`` iterations and ||Phi||
        there is at most ``DECOUPLED_GAIN`` times ||Phi(z^0)|| (judged on the residual alone); None otherwise (a
        linear-quadratic game's AVI step, or the Newton step, is taken instead). The configured z^0 stays the start
        whose plans the last round of best responses answers."""
        if self._affine():
            return None
        n = self.game.n
        alone = self._alone
        start = alone.init(state.z, state.x)
        if start.status not in FAILURES:  # the interior phase at once: Newton steps from zero inputs wander (LM steps)
            start = alone._start_interior(start, 0, k=0)
        solved = iterate(alone, start, ALONE_STEPS)
        if not solved.converged:
            return None
        z = np.concatenate([solved.z[:n], np.zeros(self.game.m)])
        L, c = self.newton.kkt_residual(z, state.x)
        phi, _ = self.newton.phi(L, c, z)
        if not norm(phi) <= DECOUPLED_GAIN * state.residual_norm:
            return None
        candidate = self.newton.advance(state, z)
        if candidate.status != Status.RUNNING:
            return None
        candidate.search = self._from(candidate, start=memory.origin, abandon=state.residual_norm, alone=solved.k,
                                      leap=PLANS_INTERIOR)
        return candidate

    @functools.cached_property
    def _alone(self) -> HybridNewton:
        """This method on the decoupled game (the rows that couple the players left out: ``Pattern.joint_rows``),
        without rounds of best responses, the line-search phase or decoupled plans of its own."""
        newton = self.newton.without_rows(self.game.pattern.joint_rows)
        newton.options = newton.options.model_copy(update={"tol": ALONE_TOL})
        alone = HybridNewton(newton)
        alone.answers = alone.decouples = alone.searches = False
        alone.plans = True
        return alone

    def _abandoned(self, state: SSNState, memory: Memory) -> SSNState:
        """The configured z^0 again as iterate k (``state``'s place), with the Newton phase from there as ``init``
        begins it: the decoupled plans' solve climbed above ||Phi(z^0)||, or its interior starts failed."""
        fresh = self.newton.advance(state, memory.start, k=state.k)
        fresh.search = self._from(fresh, alone=memory.alone)
        return fresh

    def _from(self, state: SSNState, **more) -> Memory:
        """The memory of a Newton phase that begins at ``state`` as z^0 (its merit the reference, the hand-over
        threshold from it), with ``more`` of its fields."""
        merit = state.residual_norm
        threshold = self._threshold(merit)
        return Memory(phase="newton", merits=(merit,), best=merit, stalls=0, interior=None, handover=threshold,
                      origin=state.z, handover0=threshold, **more)

    def _newton_step(self, state: SSNState, memory: Memory) -> SSNState:
        if memory.decouple:
            decoupled = self._decoupled(state, memory)
            if decoupled is not None:
                return decoupled
            memory = evolve(memory, decouple=False)
        if memory.leap:  # from the decoupled plans, or a cold start near stationary: the interior phase at once
            return self._start_interior(state, 0)
        if memory.crash:
            crashed = self._crash(state, memory)
            if crashed is not None:
                return crashed
            memory = evolve(memory, crash=False)
        candidate, regularized = self._candidate(state, memory)
        merit = candidate.residual_norm
        if (memory.interior is not None and not regularized and candidate.status == Status.RUNNING
                and merit > CORRECT_ABOVE * state.residual_norm):
            # after a hand-over: a step that climbs is corrected on the active set it points to, as a refused
            # hand-over is; where no correction helps, the climbing step goes to the watchdog as before
            corrected = self._corrected(state, candidate.z, candidate.parts.c)
            if corrected is not None:
                candidate, merit = corrected, corrected.residual_norm
        # a Levenberg-Marquardt step that barely changes ||Phi|| (neither a decrease nor a climb the watchdog may
        # allow) has met a stationary point of the merit that is no solution, and further ones stay there
        flat = regularized and abs(merit - state.residual_norm) < FLAT * state.residual_norm
        climbs = self.polish > 0.0 and not merit < state.residual_norm  # a polishing step must reduce ||Phi||
        if candidate.status == Status.RUNNING and not flat and not climbs \
                and not self._climbs_first(memory, state, merit) and merit <= BLOWUP * max(memory.merits[-MEMORY:]):
            best, stalls = memory.best, memory.stalls + 1
            if merit < (1.0 - SUFFICIENT) * best:
                best, stalls = merit, 0
            if stalls < WATCHDOG:
                return evolve(candidate, search=evolve(memory, merits=(*memory.merits[-MEMORY + 1:], merit),
                                                         best=best, stalls=stalls))
        # refused: the interior phase, at the interior iterate left at the last hand-over, or from the start
        if memory.interior is None:
            return self._start_interior(state, 0)
        it = memory.interior
        memory = evolve(memory, phase="interior", best=math.inf, stalls=0,
                         handover=0.1 * min(memory.handover, state.residual_norm))
        return self._interior_step(self.newton.advance(state, it.z, search=memory, k=state.k), memory)

    def _climbs_first(self, memory: Memory, state: SSNState, merit: float) -> bool:
        """Whether this is a Newton step of a nonlinear game's Newton phase from z^0 before any interior phase (the
        first step alone for the Fischer-Burmeister function; unperturbed, not a closed loop's warm start) and it
        raises ||Phi|| more than ``FIRST_STEP``-fold (the first step) or ``LATER_STEP``-fold (a later min-map step):
        the Newton phase then ends at once. A closed
        loop's budget of K steps from its warm start keeps the Newton step, climbing or not: an interior step from
        there leaves the last plan for a point inside every constraint (measured on MCPTrajectoryGameSolver's demo:
        at K = 1 a violation of 1.1e-3 instead of 0, at K = 5 and 10 48 and 49 of 50 sampling times converged
        instead of 50)."""
        # the min map's steps from z^0 all (an active-set search that climbs far has its guess wrong); the
        # Fischer-Burmeister function's first (its later climbs lead on: FK A.2 from 1 in 10 steps, 49 with the rule)
        first = len(memory.merits) == 1
        if not merit > (FIRST_STEP if first else LATER_STEP) * state.residual_norm:  # (most steps: at once)
            return False
        if not (first or self.newton.reduced) or memory.interior is not None or memory.attempt or memory.warm:
            return False
        return self.exact and not self._affine()

    def _start_interior(self, state: SSNState, attempt: int, *, k: int | None = None,
                        warm: bool = False) -> SSNState:
        """The interior phase from z^0 (``attempt``: which of the interior method's starting points; ``warm``:
        the warm start's instead of the first), taking one step unless ``k`` is given (then the start itself is
        the iterate k)."""
        memory: Memory = state.search
        z, w, eps = self.interior.start(memory.origin, state.x, attempt, warm)
        fast = memory.quick and attempt == 0 and not warm
        memory = evolve(memory, phase="interior", best=math.inf, stalls=0, attempt=attempt,
                         handover=memory.handover0, crash=False, decouple=False, quick=False, leap=False, fast=fast)
        start = self.newton.advance(state, z, search=memory, k=state.k if k is None else k)
        # Mehrotra's steps in the first start from z^0; the restarts and warm starts keep the monotone barrier
        predict = attempt == 0 and not warm
        memory = evolve(memory, interior=self.interior.measure(z, w, start.parts.L, start.parts.c, eps,
                                                                predict=predict, kappa=self._kappa(memory)))
        start = evolve(start, search=memory)
        return start if k is not None else self._interior_step(start, memory)

    def _kappa(self, memory: Memory) -> float:
        """The barrier's pace (eps shrinks once H_eps is solved to kappa eps): ``interior_point.KAPPA_PLANS`` in the
        decoupled game's own solve and in a trial (:meth:`_trial`), else ``interior_point.KAPPA``."""
        return interior_point.KAPPA_PLANS if self.plans or self._trial(memory) else interior_point.KAPPA

    @staticmethod
    def _trial(memory: Memory) -> bool:
        """Whether the interior phase is a trial at the faster barrier that gives way after ``FAST_STALL`` stalled
        steps: from the decoupled plans (to the configured z^0), or the first start from a start near stationary (to
        the same start at the usual pace)."""
        return memory.abandon < math.inf or memory.fast

    def _handover(self, state: SSNState) -> SSNState | None:
        """The Newton step from an interior iterate (Levenberg-Marquardt where JPhi is singular), if it reduces
        ||Phi|| HANDOVER_DECREASE-fold: judged on the residual alone, so a refused step costs no derivatives. A
        refused min-map step is tried again on the active set it points to (``HANDOVER_ROUNDS`` times at most)."""
        newton = self.newton
        z, rcond, halved, candidate, c = self._judged_point(state, state.active)
        if z is None:
            z = newton.regularized_point(state, state.residual_norm)
            if z is None:
                return None
            halved, candidate, c = self._judged(state, z, rcond)
        return candidate if halved else self._corrected(state, z, c)

    def _judged_point(self, state: SSNState, active: np.ndarray,
                      ) -> tuple[np.ndarray | None, float, bool, SSNState | None, np.ndarray | None]:
        """The Newton point from ``state`` on the g-branch rows ``active`` (None where JPhi is singular or
        ill-conditioned) and its reciprocal condition estimate (NaN where not made), judged as :meth:`_judged` judges
        it: whether it halves ||Phi||, the iterate there, c(a). The estimate is made only where the point is not kept
        on its result (a halving step that is short, see TAKEN_DECREASE): after the residual there, from the same
        factors."""
        newton = self.newton
        z, rcond = newton.newton_point(state if active is state.active else evolve(state, active=active),
                                       estimate=False)
        if z is None:
            return None, rcond, False, None, None
        halved, candidate, c = self._judged(state, z, rcond)
        if math.isnan(rcond) and not (halved and _short(state.z, z)):
            rcond = newton.reduced_system.last_rcond()
            if not rcond >= newton.options.min_rcond:
                return None, rcond, False, None, None
            if candidate is not None:
                candidate.rcond = rcond
        return z, rcond, halved, candidate, c

    def _judged(self, state: SSNState, z: np.ndarray, rcond: float) -> tuple[bool, SSNState | None, np.ndarray]:
        """Whether the point z reduces ||Phi|| HANDOVER_DECREASE-fold from ``state`` (judged on the residual alone,
        so a refused point costs no derivatives), the iterate there where it does (None where its evaluation fails),
        and c(a) at z."""
        newton = self.newton
        L, c = newton.kkt_residual(z, state.x)
        phi, _ = newton.phi(L, c, z)
        if norm(phi) > HANDOVER_DECREASE * state.residual_norm:
            return False, None, c
        candidate = newton.advance(state, z, rcond=rcond)
        return True, (candidate if candidate.status == Status.RUNNING else None), c

    def _corrected(self, state: SSNState, z: np.ndarray, c: np.ndarray) -> SSNState | None:
        """The Newton step from ``state`` on the active set that a refused step to ``z`` (c = c(a) there) points to,
        corrected up to ``HANDOVER_ROUNDS`` times as a primal-dual active-set method corrects its guess: rows whose
        multiplier came out negative leave it, rows the step violates join it (inequalities only). The first
        whose point reduces ||Phi|| HANDOVER_DECREASE-fold, judged on the residual alone; None if none does (or the
        method is not the min map without noise: its active set is not the step's)."""
        newton = self.newton
        if not newton.reduced:
            return None
        active = state.active
        for _ in range(HANDOVER_ROUNDS):
            corrected = ((active & (z[self.game.n:] >= 0.0)) | (~active & (c > 0.0))) & self._inequalities
            if np.array_equal(corrected, active):
                return None
            active = corrected
            z, _, halved, candidate, c = self._judged_point(state, active)
            if z is None:
                return None
            if halved:
                return candidate
        return None

    def _interior_step(self, state: SSNState, memory: Memory) -> SSNState:
        if state.residual_norm <= memory.handover and (
                not self.polish or self.interior.convex_at(memory.interior, state.parts)):
            candidate = self._handover(state)
            if candidate is not None:
                merit = candidate.residual_norm
                return evolve(candidate, search=evolve(memory, phase="newton", merits=(state.residual_norm, merit),
                                                         best=merit, stalls=0))
            memory = evolve(memory, handover=HANDOVER_RETRY * state.residual_norm)
        proposal = self.interior.step(memory.interior, state.parts)
        if proposal[0] is None:
            return self._restart(state, memory, Status.SINGULAR_JACOBIAN, proposal[1])
        z, w, t, rcond = proposal
        if self.handover and self.interior.I.size and state.residual_norm > RESET_ABOVE * memory.handover0:
            # the slack reset, far from a solution (the interior phase alone keeps its slacks)
            z, w = self.interior.reset_slacks(z, w, self.newton.constraint_values(z, state.x))
        new = self.newton.advance(state, z, search=memory, rcond=rcond)
        if new.status in FAILURES:  # NaN or divergence: restart if a start is left
            return self._restart(state, memory, new.status, new.message)
        it = self.interior.measure(z, w, new.parts.L, new.parts.c, memory.interior.eps, t, memory.interior.predict,
                                   memory.interior.kappa)
        best, stalls = memory.best, memory.stalls + 1
        if new.residual_norm < 0.9 * best:
            best, stalls = new.residual_norm, 0
        memory = evolve(memory, interior=it, best=best, stalls=stalls)
        if (self.searches and not memory.searched and new.k >= SLOW and not self.at_solution(new)
                and not self.game.piecewise):
            return self._start_search(new, memory)
        limit = FAST_STALL if self._trial(memory) else STALL
        if stalls >= limit:
            return self._restart(new, memory, Status.STALLED, f"||Phi|| made no progress in {limit} interior-point "
                                                               "steps")
        return evolve(new, search=memory)

    # the line-search phase ------------------------------------------------------------------
    @functools.cached_property
    def _search_method(self) -> LineSearchNewton:
        """Semismooth Newton on the Fischer-Burmeister function with Armijo backtracking, on this game (built once)."""
        options = self.options.model_copy(update={"complementarity": "fischer_burmeister",
                                                  "globalization": "line_search"})
        return LineSearchNewton(SemismoothNewton(self.game, options))

    def _start_search(self, state: SSNState, memory: Memory) -> SSNState:
        """The line-search phase from z^0 (this iteration is its first step); the interior iterate is kept to go
        back to."""
        method = self._search_method
        inner = method.init(memory.origin, state.x)
        memory = evolve(memory, phase="search", searched=True, inner=inner, steps=0)
        if inner.status in FAILURES:
            return self._end_search(state, memory)
        return self._search_step(state, memory)

    def _search_step(self, state: SSNState, memory: Memory) -> SSNState:
        """One iteration of the line-search phase; the Newton phase once ||Phi|| is small, the interior phase again
        where the search fails."""
        method = self._search_method
        inner = memory.inner
        if memory.steps >= SEARCH_STEPS or method.at_solution(inner):
            return self._end_search(state, memory)
        inner = method.step(inner)
        if inner.status in FAILURES:
            return self._end_search(state, memory)
        memory = evolve(memory, inner=inner, steps=memory.steps + 1)
        new = self.newton.advance(state, inner.z, search=memory, rcond=inner.rcond, parts=inner.parts)
        if new.status in FAILURES:
            return self._end_search(state, memory)
        if new.residual_norm <= memory.handover and not self.at_solution(new):
            return evolve(new, search=evolve(memory, phase="newton", merits=(new.residual_norm,),
                                               best=new.residual_norm, stalls=0))
        return new

    def _end_search(self, state: SSNState, memory: Memory) -> SSNState:
        """Back to the interior phase, at the interior iterate the line-search phase began from."""
        memory = evolve(memory, phase="interior", inner=None, best=math.inf, stalls=0)
        it = memory.interior
        return self._interior_step(self.newton.advance(state, it.z, search=memory, k=state.k), memory)

    def _restart(self, state: SSNState, memory: Memory, status: Status, why: str) -> SSNState:
        """After the first start from z^0 stalls, the interior phase from the players' best answers to the plans
        where it stalled (a nonlinear game of several players); else the interior phase again from z^0 with its next
        starting point; after the last, from the answers to the configured start's plans (once); for an LQ game, the
        pivoting method; or the end of the solve."""
        if memory.abandon < math.inf:  # the decoupled plans' first interior start failed: the configured z^0 again
            return self._abandoned(state, memory)
        if memory.fast:  # the first start at the faster barrier failed: the same start at the usual pace
            return self._start_interior(evolve(state, search=evolve(memory, fast=False)), 0)
        n = self.game.n
        answers = self.answers and not self._affine()
        if answers and not memory.answered and memory.attempt == 0 and status == Status.STALLED:
            answered = self._answer(state, memory, state.z[:n])
            if answered is not None:
                return answered
        if memory.attempt < RESTARTS:
            return self._start_interior(evolve(state, search=memory), memory.attempt + 1)
        if answers and not memory.answered_start:
            start = memory.origin if memory.start is None else memory.start
            answered = self._answer(state, memory, start[:n], start_plans=True)
            if answered is not None:
                return answered
            why += "; no player has a feasible best answer to the others' start plans"
        if memory.attempt < RESTARTS + PIVOTS and self.newton.condensed and self.game.affine:
            pivoted = self._pivot(state, memory)
            if pivoted is not None:
                return pivoted
            why += f"; Lemke's method ended on a ray from {PIVOTS} covering vectors"
        starts = f"{memory.attempt + 1} start(s)"
        if memory.answered:
            from_answers = memory.before + memory.attempt + 1 - memory.cold
            starts = f"{memory.cold} start(s) from z^0 and {from_answers} from the players' best answers"
        return evolve(state, status=status,
                       message=f"interior-point phase at iteration {state.k}, after {starts}: "
                               f"{why} (||Phi|| = {state.residual_norm:.2e})")

    def _affine(self) -> bool:
        """An LQ game (constant KKT derivatives), read from the formulation in use (no condensed derivatives built
        for a sparse one)."""
        return self.game.affine if self.newton.condensed else self.newton.system.affine

    def _answer(self, state: SSNState, memory: Memory, plans: np.ndarray, start_plans: bool = False) -> SSNState | None:
        """The interior phase from the players' best answers to ``plans`` (``start_plans``: the configured start's;
        one iteration: the round and the warm interior start), its other starting points after it; None if no player
        has a feasible answer."""
        a = response_round(self.game, plans, state.x)
        if a is None:
            return None
        origin = np.concatenate([a, np.zeros(self.game.m)])
        first = not memory.answered
        memory = evolve(memory, origin=origin, answered=True, answered_start=start_plans or memory.answered_start,
                         cold=memory.attempt + 1 if first else memory.cold, before=memory.before + memory.attempt + 1,
                         start=(memory.origin if memory.start is None else memory.start) if first else memory.start)
        return self._start_interior(evolve(state, search=memory), 0, warm=True)

    def _pivot(self, state: SSNState, memory: Memory) -> SSNState | None:
        """LQ games: the KKT system is a linear complementarity problem; solve it by Lemke's method from z^0 with
        the covering vectors of the remaining attempts (all ones, then seeded random ones), the first solution
        is the next iterate (one iteration). None if every attempt ends on a ray."""
        parts = self.newton.evaluate(memory.origin, state.x)[0]
        rng = np.random.default_rng(0)
        for attempt in range(memory.attempt - RESTARTS, PIVOTS):
            d = None if attempt == 0 else rng.uniform(0.1, 10.0, size=state.z.size * 4)
            z = kkt_lcp_point(parts, memory.origin, self.game.equality_mask, d)
            if z is not None:
                memory = evolve(memory, phase="newton", merits=(state.residual_norm,), best=state.residual_norm,
                                 stalls=0, interior=None, attempt=RESTARTS + PIVOTS)
                return self.newton.advance(state, z, search=memory)
        return None
