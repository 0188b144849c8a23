from os import PathLike
from typing import Any, Optional, Sequence, TypedDict, Union

import numpy as np
import numpy.typing as npt

class Generation(TypedDict):
    quantile: float
    psi: float
    psi_low: float
    psi_high: float
    achieved_psi: float
    a_expected_speed_mps: float
    a_expected_speed_marginal_mps: float
    world_xy_m: npt.NDArray[np.float64]  # [80, 2]

class CourtesyScore(TypedDict):
    psi: float
    a_expected_reward_conditional: float
    a_expected_reward_marginal: float

class Scene:
    """One traffic scenario: tracks over time and the map."""

    @staticmethod
    def from_arrays(
        scenario_id: str,
        ids: npt.NDArray[np.int64],
        states: npt.NDArray[np.float64],
        valid: npt.NDArray[np.bool_],
        object_types: Optional[Sequence[str]] = None,
        current_step: int = 10,
        sdc_id: Optional[int] = None,
        objects_of_interest: Sequence[int] = (),
        lanes: Sequence[npt.NDArray[np.float64]] = (),
        road_edges: Sequence[npt.NDArray[np.float64]] = (),
        road_lines: Sequence[npt.NDArray[np.float64]] = (),
        lane_types: Optional[Sequence[str]] = None,
    ) -> "Scene":
        """A scene from arrays: ``states [agents, steps, 7]`` = x, y, heading, vx, vy,
        length, width (metres, radians, m/s, world frame); ``valid [agents, steps]``;
        polylines ``[n, 2]``; ``lane_types`` one of ``freeway``, ``surface_street``,
        ``bike_lane``, ``undefined`` per lane (default: all undefined)."""
    @property
    def scenario_id(self) -> str: ...
    @property
    def current_step(self) -> int: ...
    @property
    def num_steps(self) -> int: ...
    @property
    def sdc_id(self) -> Optional[int]: ...
    @property
    def ids(self) -> npt.NDArray[np.int64]: ...
    @property
    def objects_of_interest(self) -> list[int]: ...
    def keep_in_lane(
        self,
        points: npt.NDArray[np.float64],
        max_offset_m: float = 0.25,
        agent_id: Optional[int] = None,
    ) -> npt.NDArray[np.float64]:
        """``points [n, 2]`` (world metres, e.g. ``generate(...)["world_xy_m"]``) kept in lane
        as scbg's closed loop keeps a plan before following it: every point pulled to within
        ``max_offset_m`` of the nearest car-lane centre line heading the plan's way, moving
        only along the map's lanes. ``agent_id``, the track whose plan it is, starts the plan
        on the lane under it (as the closed loop does). A simulator driving B from generated
        plans should follow the kept plan."""
    def states(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
        """``([agents, steps, 7], [agents, steps])`` as in :meth:`from_arrays`."""

class Simulation:
    """A closed-loop simulation (controlled agents driven by the generator)."""

    def reset(self) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
        """Back to the scene's current step: ``(ids, states [agents, 5], valid)`` with
        states x, y, heading, vx, vy."""
    def step(
        self, ego_state: Optional[npt.NDArray[np.float64]] = None
    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
        """One step; ``ego_state`` = x, y, heading, vx, vy when the ego is driven from
        outside."""
    @property
    def step_index(self) -> int: ...
    @property
    def finished(self) -> bool: ...
    @property
    def ego_id(self) -> int: ...
    def scene(self) -> Scene:
        """The scene with the simulated steps as its future."""

class Model:
    """A trained generator folder (``scbg train generator`` / the demo's ``generator_full``)."""

    def __init__(
        self, path: str, predictor: Optional[str] = None, policy: str = "generator"
    ) -> None:
        """``policy``: ``generator`` (the learned g(x, ψ)) or ``ranked`` (B's sampled futures
        chosen by their ψ labels, no generator)."""
        ...
    @property
    def variant(self) -> str: ...
    @property
    def policy(self) -> str: ...
    @property
    def audience(self) -> str:
        """Whose reward the courtesy counts: ``pair`` (A alone) or ``neighbours <r> m <sum|proximity>``."""
        ...
    @property
    def members(self) -> int:
        """How many generators plan together: 1, or an ensemble folder's members (their medoid)."""
        ...
    def generate(
        self,
        scene: Scene,
        a: int,
        b: int,
        quantile: Optional[float] = None,
        psi: Optional[float] = None,
    ) -> Generation:
        """B's future at a courtesy quantile in [0, 1] (or an explicit ψ) toward A, kept in
        lane as the closed loop keeps every plan; ``achieved_psi`` is that future's ψ."""
    def courtesy(
        self, scene: Scene, a: int, b: int, future_xy_m: npt.NDArray[np.float64]
    ) -> CourtesyScore:
        """ψ of a future of B ``[80, 2]`` (world frame) toward A."""
    def simulation(
        self,
        scene: Scene,
        controlled: dict[int, float],
        ego: Optional[int] = None,
        ego_mode: str = "external",
        others: str = "log",
        replan_every: Optional[int] = None,
    ) -> Simulation:
        """A closed-loop simulation: ``controlled`` maps track ids to courtesy quantiles
        toward the ego; ``ego_mode`` external | reactive | log; ``others`` log | reactive;
        ``replan_every`` steps between plans (default 20, 2 s, with either policy)."""

def read_scenarios(path: str) -> list[Scene]:
    """Every scenario of a WOMD file (Scenario or tf.Example TFRecord)."""

def scenarios_from_bytes(data: bytes) -> list[Scene]:
    """Every scenario of WOMD bytes (a TFRecord file or one Scenario message)."""

class WosacScore(TypedDict):
    challenge: str
    scenario_files: int
    scenarios_in_files: int
    submission_files: int
    shards: int
    not_submitted: int
    per_scenario: list[dict[str, Any]]
    aggregate: Optional[dict[str, Any]]
    skipped: dict[str, int]
    skipped_items: list[dict[str, Optional[str]]]
    seconds: float
    seconds_per_scenario: Optional[float]
    threads: int

def score_wosac(
    scenario_files: Sequence[Union[str, PathLike[str]]],
    submission_files: Sequence[Union[str, PathLike[str]]],
) -> WosacScore:
    """WOSAC 2025 realism of a submission against the logged scenarios: ``scbg eval wosac``'s
    ``wosac.json`` as a dict. Both arguments are paths, folders or glob patterns; a submission
    file is a ``SimAgentsChallengeSubmission`` shard or a ``.tar.gz`` of shards.
    ``per_scenario`` holds each scored scenario's ``metametric``, ``buckets``,
    ``likelihoods`` (ten features), ``average_displacement_error_m``,
    ``min_average_displacement_error_m``, the simulated collision, off-road and
    traffic-light-violation rates and ``seconds``; ``aggregate`` their means (None when nothing
    was scored); ``skipped_items`` everything left out with its ``reason`` and ``detail``.
    Inputs that match no file raise ``ValueError``."""
