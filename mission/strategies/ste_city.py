"""What infotaxis needs to search among known buildings: the urban likelihood and routed moves.

:class:`CitySupport` holds the buildings the mission knows (:class:`mission.obstacles.Obstacles`,
the same the safety supervisor routes around) and

- measures the inflow: down among the buildings the wind can blow the other way (paper-s4's
  start lies in block-2's lee: development seed 100 estimated N 0.98 E -2.55 m/s there, the inflow
  is N -3.3 E -3.3 at that height), so the vehicle first climbs ``probe_above_m`` above the
  tallest roof over its start and averages the estimated wind for ``probe_s`` (:meth:`probe`);
- solves the urban wind field for that inflow (about 0.5 s of CPU): in the tick that needs it, or,
  given a ``solver`` (a :class:`concurrent.futures.Executor`: the MAVSDK runner's worker process),
  off the tick -- the vehicle hovers at the probe height in state ``solve-field`` until it is done
  (:meth:`waiting`), at most ``FIELD_SOLVE_LIMIT_S``, so the setpoint stream never stops for it. The
  field is the same either way (the same function of the same inflow and buildings);
- builds the urban likelihood (``ste_urban`` over ``ste_urban_field``'s slice of the urban
  diagnostic wind, solved for that *estimated* inflow); when it cannot (no buildings, no usable
  wind, a layout that makes no scene) it says why and the strategy keeps the open-field plume
  -- a stated, simpler model -- and does not declare;
- marks candidate reading points inside a building (grown by the routing clearance) as no
  candidates, and turns a chosen goal into a heading along the shortest route around the
  buildings (:class:`mission.routing.Router`): a move toward a source behind a block goes round
  it instead of "upwind into the wall";
- notices when the vehicle reports being inside a building's footprint (the layout does not
  match the flight): such readings are weighed with the open-field plume (``SourcePosterior``),
  and after ``MISMATCH_READINGS`` of them the urban model is dropped for the rest of the mission.

Messages (one line each, for the mission log) are collected in ``messages``. Plain synchronous
deterministic code. Units SI; frame local NED (north, east) [m]; altitudes above home.
"""

from __future__ import annotations

import math
import time
from concurrent.futures import Executor, Future

import numpy as np
import shapely

from mission.obstacles import Obstacles
from mission.routing import Router
from mission.strategies.base import heading_of
from mission.strategies.ste_urban import UrbanModel, flow_at
from mission.strategies.ste_urban_field import UrbanModelError, UrbanPlane, build_plane

#: Readings inside a building's footprint after which the urban model is dropped (layout mismatch).
MISMATCH_READINGS = 3
#: Extra clearance of routed moves beyond the obstacles' margin [m] (the supervisor plans with 1 m more).
ROUTE_EXTRA_M = 1.0
#: Vehicle seconds a field solve off the tick may take (the vehicle hovers meanwhile) before the urban
#: model is given up for the mission (the open-field plume, no declaration).
FIELD_SOLVE_LIMIT_S = 30.0


class CitySupport:
    """The buildings of a search and what the urban infotaxis does with them (module docstring)."""

    def __init__(self, obstacles: Obstacles | None, cell_m: float, path_step_m: float, path_length_m: float,
                 stall: float, mix_rate: float, probe_above_m: float = 10.0, probe_s: float = 8.0,
                 altitude_m: float = 5.0) -> None:
        self.obstacles = obstacles if obstacles is not None and len(obstacles) else None
        roofs = max((b.height_m for b in self.obstacles.buildings), default=0.0) if self.obstacles else 0.0
        self.probe_height_m = roofs + probe_above_m
        self.probe_s = float(probe_s)
        self._probe = [0.0, 0.0, 0.0]  # sums of north, east wind x dt, and of dt
        self.router = Router(self.obstacles, self.obstacles.margin_m + ROUTE_EXTRA_M) if self.obstacles else None
        self.settings = (cell_m, path_step_m, path_length_m, stall, mix_rate)
        self.messages: list[str] = []
        self.model: UrbanModel | None = None
        self.solve_s = math.nan
        self.dropped = False
        self._dead_said = False
        self.altitude_m = float(altitude_m)  # the flight altitude the field is sliced at [m above home]
        self.solver: Executor | None = None  # where the field is solved off the tick (None: in the tick)
        self._job: Future[UrbanPlane] | None = None
        self._job_t0 = math.nan

    def say(self, line: str) -> None:
        self.messages.append(line)

    def probe(self, wind_ne: np.ndarray | None, altitude_m: float, dt: float, t: float = 0.0) -> np.ndarray | None:
        """One tick (vehicle time ``t`` [s]) of the inflow measurement at ``altitude_m`` [m above home]
        with the estimated wind ``wind_ne`` [m/s NED] (None: none): the mean wind [m/s NED, horizontal]
        once ``probe_s`` of it were taken within 1 m of ``probe_height_m`` (the field's solve then
        starts, :meth:`start`), else None."""
        if wind_ne is None or abs(altitude_m - self.probe_height_m) > 1.0 or not np.all(np.isfinite(wind_ne[:2])):
            return None
        b = self._probe
        b[0] += float(wind_ne[0]) * dt
        b[1] += float(wind_ne[1]) * dt
        b[2] += dt
        if b[2] < self.probe_s - 1e-9:
            return None
        inflow = np.array([b[0], b[1]]) / b[2]
        self.start(inflow, t)
        return inflow

    def start(self, wind_ne: np.ndarray, t: float) -> None:
        """Start solving the field for the inflow ``wind_ne`` [m/s NED] in ``solver`` at vehicle time
        ``t`` [s] (nothing without a solver or buildings: :meth:`build` solves it in its tick)."""
        if self.solver is None or self.obstacles is None or self._job is not None:
            return
        self._job = self.solver.submit(build_plane, list(self.obstacles.buildings), np.asarray(wind_ne, float),
                                       self.altitude_m, self.probe_height_m, self.settings[0])
        self._job_t0 = t

    def waiting(self, inflow: np.ndarray | None, t: float) -> str | None:
        """The state to hover in at ``probe_height_m`` before the search at vehicle time ``t`` [s]:
        ``measure-inflow`` (buildings and no ``inflow`` yet), ``solve-field`` (the solve off the tick
        still running, for at most ``FIELD_SOLVE_LIMIT_S``), None: the search can start."""
        if self.obstacles is None:
            return None
        if inflow is None:
            return "measure-inflow"
        job = self._job
        if job is None or job.done() or t - self._job_t0 > FIELD_SOLVE_LIMIT_S:
            return None
        return "solve-field"

    def _plane(self, wind_ne: np.ndarray, altitude_m: float) -> UrbanPlane:
        """The solved slice: the job's (its result, or why it has none) or solved here and now."""
        if self._job is None:
            assert self.obstacles is not None
            return build_plane(self.obstacles.buildings, np.asarray(wind_ne, float), altitude_m, self.probe_height_m,
                               self.settings[0])
        job, self._job = self._job, None
        if not job.done() or job.cancelled():
            job.cancel()
            raise UrbanModelError(f"the wind field was not solved within {FIELD_SOLVE_LIMIT_S:.0f} s")
        try:
            return job.result()
        except UrbanModelError:
            raise
        except Exception as e:  # noqa: BLE001 - the worker died or could not run: the open-field fallback
            raise UrbanModelError(f"the wind field's solver failed ({type(e).__name__}: {e})") from None

    def build(self, wind_ne: np.ndarray, altitude_m: float) -> UrbanModel | None:
        """The urban likelihood for the estimated inflow ``wind_ne`` [m/s NED] measured at
        ``probe_height_m``, sliced at the flight altitude ``altitude_m`` [m above home], or None
        (said why: the open-field plume is used)."""
        if self.obstacles is None:
            self.say("urban plume model: no buildings known to the mission; the open-field plume is used")
            return None
        _, step, length, stall, mix = self.settings
        t0 = time.process_time()
        off_tick = self._job is not None
        try:
            plane = self._plane(wind_ne, altitude_m)
        except UrbanModelError as e:
            self.say(f"urban plume model off: {e}; the open-field plume is used")
            return None
        self.solve_s = time.process_time() - t0
        w = plane.wind_ne
        how = "off the tick (a worker)" if off_tick else f"in {self.solve_s:.2f} s CPU"
        self.say(f"urban plume model: wind field of {len(self.obstacles)} buildings solved for the estimated inflow "
                 f"N {w[0]:.2f} E {w[1]:.2f} m/s {how}")
        self.model = UrbanModel(plane, step, length, stall, mix)
        if self.router is not None:  # the route graph now, not in the first move choice (3-4 ms)
            self.router.graph(altitude_m)
        return self.model

    def usable_at(self, point: np.ndarray) -> bool:
        """Whether the urban model can place a source at ``point`` (north, east) [m]: not in air that is
        stalled (slower than the model's stall share of the inflow) or reversed at the flight altitude
        -- a lee, a courtyard, a windward face -- where every backward path through it crosses
        straight as mixing air and cannot tell a source there from one at the wall (said once)."""
        if self.model is None:
            return True
        gp, un, ue, _ = self.model.plane.args()
        vn, ve = flow_at(gp, un, ue, float(point[0]), float(point[1]))
        ok = math.hypot(vn, ve) > self.model.stall * gp[7] and -(vn * gp[5] + ve * gp[6]) > 0.0
        if not ok and not self._dead_said:
            self._dead_said = True
            self.say(f"declaration withheld: the candidate at N {point[0]:.1f} E {point[1]:.1f} m lies in stalled or "
                     "reversed air, where the urban model cannot place a source")
        return ok

    def check_position(self, n_fallback: int) -> bool:
        """After a reading: False once ``MISMATCH_READINGS`` readings were inside a building (the
        urban model is then dropped, said once)."""
        if self.model is None or n_fallback < MISMATCH_READINGS:
            return self.model is not None
        self.say(f"urban plume model dropped: {n_fallback} readings from inside a building's footprint (the known "
                 "layout does not match the flight); the open-field plume is used from here on")
        self.model = None
        self.dropped = True
        return False

    def free(self, cx: np.ndarray, cy: np.ndarray, altitude_m: float) -> np.ndarray:
        """bool per candidate point (cx, cy) [m NED]: outside every building grown by the routing clearance."""
        if self.router is None:
            return np.ones(len(cx), dtype=bool)
        g = self.router.graph(altitude_m)
        if g is None:
            return np.ones(len(cx), dtype=bool)
        return ~shapely.intersects(g.solid, shapely.points(np.column_stack([cx, cy])))

    def heading_to(self, pos: np.ndarray, goal: np.ndarray, altitude_m: float) -> float:
        """Heading [rad] from ``pos`` toward ``goal`` (north, east) [m]: straight when nothing is in
        the way, else toward the first corner of the shortest route around the buildings."""
        if self.router is None or self.router.free_segment(pos, goal, altitude_m):
            return heading_of(goal - pos)
        route = self.router.route(pos, goal, altitude_m)
        w = route.waypoints
        for p in w[1:]:
            if float(np.hypot(*(p - pos))) > 0.5:
                return heading_of(p - pos)
        return heading_of(goal - pos)
