"""Training configuration: one frozen dataclass holds every default (the CLI is built from it)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

from crossing_assist.errors import UserError

from ..actions import VALID_SPACES
from ..data_tools.augment import field_steps
from ..geometry import FITS, TRAIN_FOV_DEG
from .backbones import list_backbones
from .heads import HEAD_KINDS

OPTIMIZERS = ("rmsprop", "adamw")
SELECT_ON = ("val", "holdout", "last")
LR_SCHEDULES = ("constant", "cosine")
CLASS_WEIGHT_POWER = {"weights": 1.0, "sqrt": 0.5}   # --balance: class weights = inverse frequency ** power
BALANCE = ("none", *CLASS_WEIGHT_POWER, "sampler")


class ConfigError(UserError):
    """An invalid training option (one line, names the option and the valid values)."""


@dataclass(frozen=True)
class TrainConfig:
    """Everything that defines a training run. Defaults follow the thesis's recipe (frozen
    backbone, RMSprop lr 2e-4 rho 0.9 eps 1e-8, cross-entropy, mirrored data) with the
    ``spatial`` head and EfficientNet-Lite0."""

    data: str
    out: str
    extra_data: tuple[str, ...] = ()    # more dataset folders whose train rows are added
    backbone: str = "efficientnet_lite0"
    weights: str = "imagenet"
    head: str = "spatial"
    feature_stride: int | None = None   # None: the backbone's own (32); 16: its stride-16 block kept too
    actions: int = 13
    epochs: int = 30
    batch_size: int = 64
    optimizer: str = "rmsprop"
    lr: float = 2e-4
    weight_decay: float = 0.0
    lr_schedule: str = "constant"       # constant | cosine (per step, from lr down to 0 at the last epoch)
    p: float = 0.5                      # MC dropout probability of the head
    mirror: bool = True
    yaw: tuple[float, ...] = ()         # fixed yaw angles (degrees), each used as +-angle
    field: int = 0                      # random field views per frame (roll, phone aspect, corruption)
    field_without: tuple[str, ...] = ()  # field-view steps or corruptions left out (an ablation)
    field_zoom: float = 1.0             # > 1: half the field views magnified by 1..field_zoom
    fov_deg: float = TRAIN_FOV_DEG      # horizontal FOV assumed for the training photos
    input_size: tuple[int, int] | None = None   # (H, W) canvas; None = the backbone's own
    fit: str = "letterbox"              # how a frame meets the canvas: letterbox | stretch
    unfreeze: int = 0                   # last backbone blocks trained (0 = frozen backbone)
    balance: str = "none"               # none | weights (class-weighted loss) | sqrt (weights ** 0.5) | sampler
    smoothing: float = 0.0              # label mass moved to the neighbouring bins
    aux_x: float = 0.0                  # weight of the |E[x] - far_x| auxiliary loss
    soft_x: float = 0.0                 # > 0: targets from a Gaussian around far_x (sd in strip widths)
    select_on: str = "val"              # val | holdout | last: which set picks best.pt
    holdout: tuple[str, ...] = ()       # train sources held out for model selection
    seed: int = 0
    threads: int = 1                    # torch threads; 1 is fastest on a busy shared CPU
    cache_dir: str = "runs/.cache"
    progress: bool = True

    def __post_init__(self) -> None:
        check = [
            (self.backbone in list_backbones(), f"backbone {self.backbone!r}; valid: {', '.join(list_backbones())}"),
            (self.feature_stride in (None, 16, 32), f"feature_stride {self.feature_stride}; valid: 16, 32"),
            (self.head in HEAD_KINDS, f"head {self.head!r}; valid: {', '.join(HEAD_KINDS)}"),
            (self.actions in VALID_SPACES, f"actions {self.actions}; valid: 4, 8, 13"),
            (self.epochs >= 1, f"epochs {self.epochs}; valid: >= 1"),
            (self.batch_size >= 1, f"batch_size {self.batch_size}; valid: >= 1"),
            (self.optimizer in OPTIMIZERS, f"optimizer {self.optimizer!r}; valid: {', '.join(OPTIMIZERS)}"),
            (self.lr > 0, f"lr {self.lr}; valid: > 0"),
            (self.lr_schedule in LR_SCHEDULES, f"lr_schedule {self.lr_schedule!r}; valid: {', '.join(LR_SCHEDULES)}"),
            (0 <= self.p < 1, f"p {self.p}; valid: 0 <= p < 1"),
            (self.unfreeze >= 0, f"unfreeze {self.unfreeze}; valid: >= 0"),
            (self.balance in BALANCE, f"balance {self.balance!r}; valid: {', '.join(BALANCE)}"),
            (0 <= self.smoothing < 1, f"smoothing {self.smoothing}; valid: 0 <= s < 1"),
            (self.aux_x >= 0, f"aux_x {self.aux_x}; valid: >= 0"),
            (0 <= self.soft_x <= 3, f"soft_x {self.soft_x}; valid: 0 <= sd <= 3 strip widths"),
            (self.select_on in SELECT_ON, f"select_on {self.select_on!r}; valid: {', '.join(SELECT_ON)}"),
            (self.select_on != "holdout" or bool(self.holdout), "select_on holdout needs --holdout SOURCE"),
            (all(0 < abs(a) < 45 for a in self.yaw), f"yaw {self.yaw}; valid: angles with 0 < |a| < 45"),
            (self.threads >= 1, f"threads {self.threads}; valid: >= 1"),
            (self.fit in FITS, f"fit {self.fit!r}; valid: {', '.join(FITS)}"),
            (0 <= self.field <= 16, f"field {self.field}; valid: 0..16"),
            (set(self.field_without) <= set(field_steps()),
             f"field_without {','.join(self.field_without)}; valid: {', '.join(field_steps())}"),
            (not self.field_without or self.field > 0, "field_without needs --field >= 1"),
            (1 <= self.field_zoom <= 4, f"field_zoom {self.field_zoom}; valid: 1..4"),
            (self.field_zoom == 1 or self.field > 0, "field_zoom needs --field >= 1"),
            (self.input_size is None or min(self.input_size) >= 16, f"input_size {self.input_size}; valid: >= 16 px"),
        ]
        for ok, msg in check:
            if not ok:
                raise ConfigError(f"Invalid {msg}")

    def to_dict(self) -> dict:
        """Plain types (tuples as lists) for args.yaml."""
        d = asdict(self)
        for k, v in d.items():
            if isinstance(v, tuple):
                d[k] = list(v)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "TrainConfig":
        names = {f.name for f in fields(cls)}
        kw = {k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items() if k in names}
        return cls(**kw)
