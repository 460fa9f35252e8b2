from google.protobuf.internal import containers as _containers
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class Tensor(_message.Message):
    __slots__ = ("name", "dtype", "shape", "data")
    NAME_FIELD_NUMBER: _ClassVar[int]
    DTYPE_FIELD_NUMBER: _ClassVar[int]
    SHAPE_FIELD_NUMBER: _ClassVar[int]
    DATA_FIELD_NUMBER: _ClassVar[int]
    name: str
    dtype: str
    shape: _containers.RepeatedScalarFieldContainer[int]
    data: bytes
    def __init__(self, name: _Optional[str] = ..., dtype: _Optional[str] = ..., shape: _Optional[_Iterable[int]] = ..., data: _Optional[bytes] = ...) -> None: ...

class SensorSpec(_message.Message):
    __slots__ = ("name", "dtype", "shape", "low", "high", "description")
    NAME_FIELD_NUMBER: _ClassVar[int]
    DTYPE_FIELD_NUMBER: _ClassVar[int]
    SHAPE_FIELD_NUMBER: _ClassVar[int]
    LOW_FIELD_NUMBER: _ClassVar[int]
    HIGH_FIELD_NUMBER: _ClassVar[int]
    DESCRIPTION_FIELD_NUMBER: _ClassVar[int]
    name: str
    dtype: str
    shape: _containers.RepeatedScalarFieldContainer[int]
    low: float
    high: float
    description: str
    def __init__(self, name: _Optional[str] = ..., dtype: _Optional[str] = ..., shape: _Optional[_Iterable[int]] = ..., low: _Optional[float] = ..., high: _Optional[float] = ..., description: _Optional[str] = ...) -> None: ...

class ActionSpace(_message.Message):
    __slots__ = ("discrete_n", "low", "high", "names")
    DISCRETE_N_FIELD_NUMBER: _ClassVar[int]
    LOW_FIELD_NUMBER: _ClassVar[int]
    HIGH_FIELD_NUMBER: _ClassVar[int]
    NAMES_FIELD_NUMBER: _ClassVar[int]
    discrete_n: int
    low: _containers.RepeatedScalarFieldContainer[float]
    high: _containers.RepeatedScalarFieldContainer[float]
    names: _containers.RepeatedScalarFieldContainer[str]
    def __init__(self, discrete_n: _Optional[int] = ..., low: _Optional[_Iterable[float]] = ..., high: _Optional[_Iterable[float]] = ..., names: _Optional[_Iterable[str]] = ...) -> None: ...

class WorldSpec(_message.Message):
    __slots__ = ("schema_version", "world_id", "kind", "sensors", "action_space", "reward_min", "reward_max", "program", "n_starts", "params", "session", "goal")
    class ParamsEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: str
        def __init__(self, key: _Optional[str] = ..., value: _Optional[str] = ...) -> None: ...
    SCHEMA_VERSION_FIELD_NUMBER: _ClassVar[int]
    WORLD_ID_FIELD_NUMBER: _ClassVar[int]
    KIND_FIELD_NUMBER: _ClassVar[int]
    SENSORS_FIELD_NUMBER: _ClassVar[int]
    ACTION_SPACE_FIELD_NUMBER: _ClassVar[int]
    REWARD_MIN_FIELD_NUMBER: _ClassVar[int]
    REWARD_MAX_FIELD_NUMBER: _ClassVar[int]
    PROGRAM_FIELD_NUMBER: _ClassVar[int]
    N_STARTS_FIELD_NUMBER: _ClassVar[int]
    PARAMS_FIELD_NUMBER: _ClassVar[int]
    SESSION_FIELD_NUMBER: _ClassVar[int]
    GOAL_FIELD_NUMBER: _ClassVar[int]
    schema_version: int
    world_id: str
    kind: str
    sensors: _containers.RepeatedCompositeFieldContainer[SensorSpec]
    action_space: ActionSpace
    reward_min: float
    reward_max: float
    program: str
    n_starts: int
    params: _containers.ScalarMap[str, str]
    session: str
    goal: str
    def __init__(self, schema_version: _Optional[int] = ..., world_id: _Optional[str] = ..., kind: _Optional[str] = ..., sensors: _Optional[_Iterable[_Union[SensorSpec, _Mapping]]] = ..., action_space: _Optional[_Union[ActionSpace, _Mapping]] = ..., reward_min: _Optional[float] = ..., reward_max: _Optional[float] = ..., program: _Optional[str] = ..., n_starts: _Optional[int] = ..., params: _Optional[_Mapping[str, str]] = ..., session: _Optional[str] = ..., goal: _Optional[str] = ...) -> None: ...

class Observation(_message.Message):
    __slots__ = ("schema_version", "world_id", "episode", "step", "t", "timestamp", "tensors", "reward", "done", "start", "session", "truncated", "success")
    SCHEMA_VERSION_FIELD_NUMBER: _ClassVar[int]
    WORLD_ID_FIELD_NUMBER: _ClassVar[int]
    EPISODE_FIELD_NUMBER: _ClassVar[int]
    STEP_FIELD_NUMBER: _ClassVar[int]
    T_FIELD_NUMBER: _ClassVar[int]
    TIMESTAMP_FIELD_NUMBER: _ClassVar[int]
    TENSORS_FIELD_NUMBER: _ClassVar[int]
    REWARD_FIELD_NUMBER: _ClassVar[int]
    DONE_FIELD_NUMBER: _ClassVar[int]
    START_FIELD_NUMBER: _ClassVar[int]
    SESSION_FIELD_NUMBER: _ClassVar[int]
    TRUNCATED_FIELD_NUMBER: _ClassVar[int]
    SUCCESS_FIELD_NUMBER: _ClassVar[int]
    schema_version: int
    world_id: str
    episode: int
    step: int
    t: int
    timestamp: float
    tensors: _containers.RepeatedCompositeFieldContainer[Tensor]
    reward: float
    done: bool
    start: int
    session: str
    truncated: bool
    success: bool
    def __init__(self, schema_version: _Optional[int] = ..., world_id: _Optional[str] = ..., episode: _Optional[int] = ..., step: _Optional[int] = ..., t: _Optional[int] = ..., timestamp: _Optional[float] = ..., tensors: _Optional[_Iterable[_Union[Tensor, _Mapping]]] = ..., reward: _Optional[float] = ..., done: _Optional[bool] = ..., start: _Optional[int] = ..., session: _Optional[str] = ..., truncated: _Optional[bool] = ..., success: _Optional[bool] = ...) -> None: ...

class Action(_message.Message):
    __slots__ = ("schema_version", "world_id", "step", "values", "reset", "start", "timestamp", "owner", "epoch")
    SCHEMA_VERSION_FIELD_NUMBER: _ClassVar[int]
    WORLD_ID_FIELD_NUMBER: _ClassVar[int]
    STEP_FIELD_NUMBER: _ClassVar[int]
    VALUES_FIELD_NUMBER: _ClassVar[int]
    RESET_FIELD_NUMBER: _ClassVar[int]
    START_FIELD_NUMBER: _ClassVar[int]
    TIMESTAMP_FIELD_NUMBER: _ClassVar[int]
    OWNER_FIELD_NUMBER: _ClassVar[int]
    EPOCH_FIELD_NUMBER: _ClassVar[int]
    schema_version: int
    world_id: str
    step: int
    values: _containers.RepeatedScalarFieldContainer[float]
    reset: bool
    start: int
    timestamp: float
    owner: str
    epoch: int
    def __init__(self, schema_version: _Optional[int] = ..., world_id: _Optional[str] = ..., step: _Optional[int] = ..., values: _Optional[_Iterable[float]] = ..., reset: _Optional[bool] = ..., start: _Optional[int] = ..., timestamp: _Optional[float] = ..., owner: _Optional[str] = ..., epoch: _Optional[int] = ...) -> None: ...

class Control(_message.Message):
    __slots__ = ("schema_version", "world_id", "kind", "params", "timestamp", "id")
    class ParamsEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: str
        def __init__(self, key: _Optional[str] = ..., value: _Optional[str] = ...) -> None: ...
    SCHEMA_VERSION_FIELD_NUMBER: _ClassVar[int]
    WORLD_ID_FIELD_NUMBER: _ClassVar[int]
    KIND_FIELD_NUMBER: _ClassVar[int]
    PARAMS_FIELD_NUMBER: _ClassVar[int]
    TIMESTAMP_FIELD_NUMBER: _ClassVar[int]
    ID_FIELD_NUMBER: _ClassVar[int]
    schema_version: int
    world_id: str
    kind: str
    params: _containers.ScalarMap[str, str]
    timestamp: float
    id: int
    def __init__(self, schema_version: _Optional[int] = ..., world_id: _Optional[str] = ..., kind: _Optional[str] = ..., params: _Optional[_Mapping[str, str]] = ..., timestamp: _Optional[float] = ..., id: _Optional[int] = ...) -> None: ...

class Truth(_message.Message):
    __slots__ = ("schema_version", "world_id", "kind", "tensors", "step", "timestamp")
    SCHEMA_VERSION_FIELD_NUMBER: _ClassVar[int]
    WORLD_ID_FIELD_NUMBER: _ClassVar[int]
    KIND_FIELD_NUMBER: _ClassVar[int]
    TENSORS_FIELD_NUMBER: _ClassVar[int]
    STEP_FIELD_NUMBER: _ClassVar[int]
    TIMESTAMP_FIELD_NUMBER: _ClassVar[int]
    schema_version: int
    world_id: str
    kind: str
    tensors: _containers.RepeatedCompositeFieldContainer[Tensor]
    step: int
    timestamp: float
    def __init__(self, schema_version: _Optional[int] = ..., world_id: _Optional[str] = ..., kind: _Optional[str] = ..., tensors: _Optional[_Iterable[_Union[Tensor, _Mapping]]] = ..., step: _Optional[int] = ..., timestamp: _Optional[float] = ...) -> None: ...

class Embedding(_message.Message):
    __slots__ = ("schema_version", "agent_id", "world_id", "version", "trigger", "ids", "coordinates", "eigenvalues", "has_procrustes", "procrustes_error", "step", "timestamp", "metrics", "iteration", "drop_step", "labels", "scores")
    class MetricsEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: float
        def __init__(self, key: _Optional[str] = ..., value: _Optional[float] = ...) -> None: ...
    class Scores(_message.Message):
        __slots__ = ("trustworthiness", "continuity", "metric_dissimilarity", "topological_dissimilarity", "n_neighbors", "n_points")
        TRUSTWORTHINESS_FIELD_NUMBER: _ClassVar[int]
        CONTINUITY_FIELD_NUMBER: _ClassVar[int]
        METRIC_DISSIMILARITY_FIELD_NUMBER: _ClassVar[int]
        TOPOLOGICAL_DISSIMILARITY_FIELD_NUMBER: _ClassVar[int]
        N_NEIGHBORS_FIELD_NUMBER: _ClassVar[int]
        N_POINTS_FIELD_NUMBER: _ClassVar[int]
        trustworthiness: float
        continuity: float
        metric_dissimilarity: float
        topological_dissimilarity: float
        n_neighbors: int
        n_points: int
        def __init__(self, trustworthiness: _Optional[float] = ..., continuity: _Optional[float] = ..., metric_dissimilarity: _Optional[float] = ..., topological_dissimilarity: _Optional[float] = ..., n_neighbors: _Optional[int] = ..., n_points: _Optional[int] = ...) -> None: ...
    SCHEMA_VERSION_FIELD_NUMBER: _ClassVar[int]
    AGENT_ID_FIELD_NUMBER: _ClassVar[int]
    WORLD_ID_FIELD_NUMBER: _ClassVar[int]
    VERSION_FIELD_NUMBER: _ClassVar[int]
    TRIGGER_FIELD_NUMBER: _ClassVar[int]
    IDS_FIELD_NUMBER: _ClassVar[int]
    COORDINATES_FIELD_NUMBER: _ClassVar[int]
    EIGENVALUES_FIELD_NUMBER: _ClassVar[int]
    HAS_PROCRUSTES_FIELD_NUMBER: _ClassVar[int]
    PROCRUSTES_ERROR_FIELD_NUMBER: _ClassVar[int]
    STEP_FIELD_NUMBER: _ClassVar[int]
    TIMESTAMP_FIELD_NUMBER: _ClassVar[int]
    METRICS_FIELD_NUMBER: _ClassVar[int]
    ITERATION_FIELD_NUMBER: _ClassVar[int]
    DROP_STEP_FIELD_NUMBER: _ClassVar[int]
    LABELS_FIELD_NUMBER: _ClassVar[int]
    SCORES_FIELD_NUMBER: _ClassVar[int]
    schema_version: int
    agent_id: str
    world_id: str
    version: int
    trigger: str
    ids: _containers.RepeatedScalarFieldContainer[int]
    coordinates: Tensor
    eigenvalues: _containers.RepeatedScalarFieldContainer[float]
    has_procrustes: bool
    procrustes_error: float
    step: int
    timestamp: float
    metrics: _containers.ScalarMap[str, float]
    iteration: int
    drop_step: int
    labels: _containers.RepeatedScalarFieldContainer[int]
    scores: Embedding.Scores
    def __init__(self, schema_version: _Optional[int] = ..., agent_id: _Optional[str] = ..., world_id: _Optional[str] = ..., version: _Optional[int] = ..., trigger: _Optional[str] = ..., ids: _Optional[_Iterable[int]] = ..., coordinates: _Optional[_Union[Tensor, _Mapping]] = ..., eigenvalues: _Optional[_Iterable[float]] = ..., has_procrustes: _Optional[bool] = ..., procrustes_error: _Optional[float] = ..., step: _Optional[int] = ..., timestamp: _Optional[float] = ..., metrics: _Optional[_Mapping[str, float]] = ..., iteration: _Optional[int] = ..., drop_step: _Optional[int] = ..., labels: _Optional[_Iterable[int]] = ..., scores: _Optional[_Union[Embedding.Scores, _Mapping]] = ...) -> None: ...

class AttachConfig(_message.Message):
    __slots__ = ("seed", "detector", "program", "program_params")
    class ProgramParamsEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: str
        def __init__(self, key: _Optional[str] = ..., value: _Optional[str] = ...) -> None: ...
    SEED_FIELD_NUMBER: _ClassVar[int]
    DETECTOR_FIELD_NUMBER: _ClassVar[int]
    PROGRAM_FIELD_NUMBER: _ClassVar[int]
    PROGRAM_PARAMS_FIELD_NUMBER: _ClassVar[int]
    seed: int
    detector: str
    program: str
    program_params: _containers.ScalarMap[str, str]
    def __init__(self, seed: _Optional[int] = ..., detector: _Optional[str] = ..., program: _Optional[str] = ..., program_params: _Optional[_Mapping[str, str]] = ...) -> None: ...

class AgentEvent(_message.Message):
    __slots__ = ("schema_version", "agent_id", "world_id", "kind", "detail", "step", "timestamp", "values", "reason", "config")
    class ValuesEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: float
        def __init__(self, key: _Optional[str] = ..., value: _Optional[float] = ...) -> None: ...
    SCHEMA_VERSION_FIELD_NUMBER: _ClassVar[int]
    AGENT_ID_FIELD_NUMBER: _ClassVar[int]
    WORLD_ID_FIELD_NUMBER: _ClassVar[int]
    KIND_FIELD_NUMBER: _ClassVar[int]
    DETAIL_FIELD_NUMBER: _ClassVar[int]
    STEP_FIELD_NUMBER: _ClassVar[int]
    TIMESTAMP_FIELD_NUMBER: _ClassVar[int]
    VALUES_FIELD_NUMBER: _ClassVar[int]
    REASON_FIELD_NUMBER: _ClassVar[int]
    CONFIG_FIELD_NUMBER: _ClassVar[int]
    schema_version: int
    agent_id: str
    world_id: str
    kind: str
    detail: str
    step: int
    timestamp: float
    values: _containers.ScalarMap[str, float]
    reason: str
    config: AttachConfig
    def __init__(self, schema_version: _Optional[int] = ..., agent_id: _Optional[str] = ..., world_id: _Optional[str] = ..., kind: _Optional[str] = ..., detail: _Optional[str] = ..., step: _Optional[int] = ..., timestamp: _Optional[float] = ..., values: _Optional[_Mapping[str, float]] = ..., reason: _Optional[str] = ..., config: _Optional[_Union[AttachConfig, _Mapping]] = ...) -> None: ...

class WorldEvent(_message.Message):
    __slots__ = ("schema_version", "world_id", "session", "kind", "reason", "detail", "step", "timestamp", "control_id", "owner", "epoch", "holder", "holder_epoch")
    SCHEMA_VERSION_FIELD_NUMBER: _ClassVar[int]
    WORLD_ID_FIELD_NUMBER: _ClassVar[int]
    SESSION_FIELD_NUMBER: _ClassVar[int]
    KIND_FIELD_NUMBER: _ClassVar[int]
    REASON_FIELD_NUMBER: _ClassVar[int]
    DETAIL_FIELD_NUMBER: _ClassVar[int]
    STEP_FIELD_NUMBER: _ClassVar[int]
    TIMESTAMP_FIELD_NUMBER: _ClassVar[int]
    CONTROL_ID_FIELD_NUMBER: _ClassVar[int]
    OWNER_FIELD_NUMBER: _ClassVar[int]
    EPOCH_FIELD_NUMBER: _ClassVar[int]
    HOLDER_FIELD_NUMBER: _ClassVar[int]
    HOLDER_EPOCH_FIELD_NUMBER: _ClassVar[int]
    schema_version: int
    world_id: str
    session: str
    kind: str
    reason: str
    detail: str
    step: int
    timestamp: float
    control_id: int
    owner: str
    epoch: int
    holder: str
    holder_epoch: int
    def __init__(self, schema_version: _Optional[int] = ..., world_id: _Optional[str] = ..., session: _Optional[str] = ..., kind: _Optional[str] = ..., reason: _Optional[str] = ..., detail: _Optional[str] = ..., step: _Optional[int] = ..., timestamp: _Optional[float] = ..., control_id: _Optional[int] = ..., owner: _Optional[str] = ..., epoch: _Optional[int] = ..., holder: _Optional[str] = ..., holder_epoch: _Optional[int] = ...) -> None: ...

class LeaseRequest(_message.Message):
    __slots__ = ("schema_version", "world_id", "owner", "epoch", "release", "request_id")
    SCHEMA_VERSION_FIELD_NUMBER: _ClassVar[int]
    WORLD_ID_FIELD_NUMBER: _ClassVar[int]
    OWNER_FIELD_NUMBER: _ClassVar[int]
    EPOCH_FIELD_NUMBER: _ClassVar[int]
    RELEASE_FIELD_NUMBER: _ClassVar[int]
    REQUEST_ID_FIELD_NUMBER: _ClassVar[int]
    schema_version: int
    world_id: str
    owner: str
    epoch: int
    release: bool
    request_id: str
    def __init__(self, schema_version: _Optional[int] = ..., world_id: _Optional[str] = ..., owner: _Optional[str] = ..., epoch: _Optional[int] = ..., release: _Optional[bool] = ..., request_id: _Optional[str] = ...) -> None: ...

class Lease(_message.Message):
    __slots__ = ("schema_version", "world_id", "session", "holder", "epoch", "granted", "reason", "ttl", "timestamp")
    SCHEMA_VERSION_FIELD_NUMBER: _ClassVar[int]
    WORLD_ID_FIELD_NUMBER: _ClassVar[int]
    SESSION_FIELD_NUMBER: _ClassVar[int]
    HOLDER_FIELD_NUMBER: _ClassVar[int]
    EPOCH_FIELD_NUMBER: _ClassVar[int]
    GRANTED_FIELD_NUMBER: _ClassVar[int]
    REASON_FIELD_NUMBER: _ClassVar[int]
    TTL_FIELD_NUMBER: _ClassVar[int]
    TIMESTAMP_FIELD_NUMBER: _ClassVar[int]
    schema_version: int
    world_id: str
    session: str
    holder: str
    epoch: int
    granted: bool
    reason: str
    ttl: float
    timestamp: float
    def __init__(self, schema_version: _Optional[int] = ..., world_id: _Optional[str] = ..., session: _Optional[str] = ..., holder: _Optional[str] = ..., epoch: _Optional[int] = ..., granted: _Optional[bool] = ..., reason: _Optional[str] = ..., ttl: _Optional[float] = ..., timestamp: _Optional[float] = ...) -> None: ...

class Checkpoint(_message.Message):
    __slots__ = ("schema_version", "world_id", "owner", "epoch", "format_version", "embedding_version", "saved_at", "data")
    SCHEMA_VERSION_FIELD_NUMBER: _ClassVar[int]
    WORLD_ID_FIELD_NUMBER: _ClassVar[int]
    OWNER_FIELD_NUMBER: _ClassVar[int]
    EPOCH_FIELD_NUMBER: _ClassVar[int]
    FORMAT_VERSION_FIELD_NUMBER: _ClassVar[int]
    EMBEDDING_VERSION_FIELD_NUMBER: _ClassVar[int]
    SAVED_AT_FIELD_NUMBER: _ClassVar[int]
    DATA_FIELD_NUMBER: _ClassVar[int]
    schema_version: int
    world_id: str
    owner: str
    epoch: int
    format_version: int
    embedding_version: int
    saved_at: float
    data: bytes
    def __init__(self, schema_version: _Optional[int] = ..., world_id: _Optional[str] = ..., owner: _Optional[str] = ..., epoch: _Optional[int] = ..., format_version: _Optional[int] = ..., embedding_version: _Optional[int] = ..., saved_at: _Optional[float] = ..., data: _Optional[bytes] = ...) -> None: ...

class LinkStatus(_message.Message):
    __slots__ = ("world_id", "kind", "program", "state", "steps", "episodes", "embedding_version", "reward_mean", "rejected", "last_procrustes_error", "detector_statistic", "drops", "dropped")
    class RejectedEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: int
        def __init__(self, key: _Optional[str] = ..., value: _Optional[int] = ...) -> None: ...
    WORLD_ID_FIELD_NUMBER: _ClassVar[int]
    KIND_FIELD_NUMBER: _ClassVar[int]
    PROGRAM_FIELD_NUMBER: _ClassVar[int]
    STATE_FIELD_NUMBER: _ClassVar[int]
    STEPS_FIELD_NUMBER: _ClassVar[int]
    EPISODES_FIELD_NUMBER: _ClassVar[int]
    EMBEDDING_VERSION_FIELD_NUMBER: _ClassVar[int]
    REWARD_MEAN_FIELD_NUMBER: _ClassVar[int]
    REJECTED_FIELD_NUMBER: _ClassVar[int]
    LAST_PROCRUSTES_ERROR_FIELD_NUMBER: _ClassVar[int]
    DETECTOR_STATISTIC_FIELD_NUMBER: _ClassVar[int]
    DROPS_FIELD_NUMBER: _ClassVar[int]
    DROPPED_FIELD_NUMBER: _ClassVar[int]
    world_id: str
    kind: str
    program: str
    state: str
    steps: int
    episodes: int
    embedding_version: int
    reward_mean: float
    rejected: _containers.ScalarMap[str, int]
    last_procrustes_error: float
    detector_statistic: float
    drops: int
    dropped: int
    def __init__(self, world_id: _Optional[str] = ..., kind: _Optional[str] = ..., program: _Optional[str] = ..., state: _Optional[str] = ..., steps: _Optional[int] = ..., episodes: _Optional[int] = ..., embedding_version: _Optional[int] = ..., reward_mean: _Optional[float] = ..., rejected: _Optional[_Mapping[str, int]] = ..., last_procrustes_error: _Optional[float] = ..., detector_statistic: _Optional[float] = ..., drops: _Optional[int] = ..., dropped: _Optional[int] = ...) -> None: ...

class AgentStatus(_message.Message):
    __slots__ = ("schema_version", "agent_id", "uptime", "links", "counters", "timestamp")
    class CountersEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: int
        def __init__(self, key: _Optional[str] = ..., value: _Optional[int] = ...) -> None: ...
    SCHEMA_VERSION_FIELD_NUMBER: _ClassVar[int]
    AGENT_ID_FIELD_NUMBER: _ClassVar[int]
    UPTIME_FIELD_NUMBER: _ClassVar[int]
    LINKS_FIELD_NUMBER: _ClassVar[int]
    COUNTERS_FIELD_NUMBER: _ClassVar[int]
    TIMESTAMP_FIELD_NUMBER: _ClassVar[int]
    schema_version: int
    agent_id: str
    uptime: float
    links: _containers.RepeatedCompositeFieldContainer[LinkStatus]
    counters: _containers.ScalarMap[str, int]
    timestamp: float
    def __init__(self, schema_version: _Optional[int] = ..., agent_id: _Optional[str] = ..., uptime: _Optional[float] = ..., links: _Optional[_Iterable[_Union[LinkStatus, _Mapping]]] = ..., counters: _Optional[_Mapping[str, int]] = ..., timestamp: _Optional[float] = ...) -> None: ...
