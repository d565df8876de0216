"""Configuration and outputs of :class:`~strl_pyg.model.strl_pose.StrLPose` (imported from
:mod:`strl_pyg.model.strl_pose`)."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import torch
from torch import Tensor

from strl_pyg.geometry import Pose, quaternion_to_rotation
from strl_pyg.nn.encoders import INPUT_MODES
from strl_pyg.nn.heads import TRANSLATION_MODES
from strl_pyg.utils.dataclass import strict_from_dict

__all__ = ["StrLPoseConfig", "PoseOutput", "GeometricOutput", "ABLATIONS", "NO_INTRINSICS",
           "VISUAL_MODES", "PAPER"]

ABLATIONS: dict[str, dict[str, Any]] = {
    "baseline": dict(use_lines=False, line_mp=False, visual=None, visual_graph=False,
                     weighted=False),
    "L": dict(use_lines=True, line_mp=False, visual=None, visual_graph=False, weighted=False),
    "LP": dict(use_lines=True, line_mp=True, visual=None, visual_graph=False, weighted=False),
    "R": dict(use_lines=False, line_mp=False, visual="cnn", visual_graph=False, weighted=False),
    "V": dict(use_lines=False, line_mp=False, visual="pixel", visual_graph=True,
              weighted=False),
    "LP+R": dict(use_lines=True, line_mp=True, visual="cnn", visual_graph=False,
                 weighted=False),
    "LP+V": dict(use_lines=True, line_mp=True, visual="pixel", visual_graph=True,
                 weighted=False),
    "V+W": dict(use_lines=False, line_mp=False, visual="pixel", visual_graph=True,
                weighted=True),
    "full": dict(use_lines=True, line_mp=True, visual="pixel", visual_graph=True,
                 weighted=True),
}

VISUAL_MODES = (None, "pixel", "cnn")

#: The paper's own choices where the package departs from them by default: its node inputs
#: (the four coordinates, ``inputs="paper"``). ``StrLPoseConfig.ablation(row, **PAPER)`` is a
#: row of Table 3 exactly as the paper describes it; training with ``--loss paper`` adds the
#: paper's aleatoric loss (:class:`strl_pyg.training.loss.PoseLoss`).
PAPER: dict[str, Any] = {"inputs": "paper"}


@dataclass
class StrLPoseConfig:
    """Configuration of :class:`StrLPose`. The defaults are the full model (``"full"``).

    The paper leaves width, depth and heads open; the defaults follow its closest relative,
    UA-Fusion (Zhuang & Chandraker, CVPR 2021): width 128, four attention layers, four heads.
    """

    hidden: int = 128  # node feature width C of both streams
    layers: int = 4  # dual-graph layers; each is GCG self-attn (+ line MP) (+ GGVG self + cross)
    heads: int = 4  # attention heads; must divide `hidden`
    mlp_ratio: int = 2  # hidden width of every residual update MLP, as a multiple of `hidden`
    line_channels: int = 64  # width of the LSE line-segment feature f0_L
    use_lines: bool = True  # "+L": line endpoints become nodes (SCE-encoded like points)
    line_mp: bool = True  # "+LP": line-endpoint message passing with LSE features
    visual: str | None = "pixel"  # None | "pixel" (PE on patch0/1, "+V") | "cnn" (image0/1, "+R")
    visual_graph: bool = True  # GGVG layers (visual self-attn + geometry-guided cross-attn)
    weighted: bool = True  # "+W": sigmoid-gated pooling in the fusion head (else mean pooling)
    patch_features: int = 3  # per-image features of patch0/patch1 (C * p * p; RGB, p = 1)
    image_channels: int = 3  # channels of image0/image1 for visual="cnn"
    translation: str = "direction"  # "direction" (unit vector, scale-free data) | "metric"
    # node inputs of the SCE: "flow" (beyond the paper: coordinates, displacement and its
    # divergence / curl products, standardised) | "flow2" ("flow" and two second-order
    # rotation products) | "parallax" ("flow" and each node's motion parallax against its
    # image neighbours with the epipole's least-squares products) | "paper" (the four
    # coordinates); a checkpoint
    # saved without this key was trained with "paper" (from_dict)
    inputs: str = "flow"
    dropout: float = 0.0  # attention-weight dropout
    # Beyond the paper: the geometric head (per-node inlier logits -> weighted essential solve,
    # strl_pyg.geometry.essential). The paper's regression head is always present; this adds a
    # second
    # output, trained jointly (strl_pyg.training.loss.GeometricLoss).
    geometric: bool = False
    geometric_iterations: int = 2  # IRLS rounds after the weighted eight-point solve
    geometric_tau: float = 2e-3  # Cauchy scale of the IRLS kernel, normalised units

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        for name in ("hidden", "layers", "heads", "mlp_ratio", "line_channels",
                     "patch_features", "image_channels"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ValueError(f"Expected a positive integer '{name}' (got {value!r})")
        if self.hidden % self.heads:
            raise ValueError(
                f"Expected heads to divide hidden (got hidden={self.hidden}, heads={self.heads})"
            )
        if self.visual not in VISUAL_MODES:
            raise ValueError(f"Expected visual in {VISUAL_MODES} (got {self.visual!r})")
        if self.visual_graph and self.visual is None:
            raise ValueError("Expected a visual encoder for visual_graph=True (got visual=None)")
        if self.line_mp and not self.use_lines:
            raise ValueError("Expected use_lines=True for line_mp=True (got use_lines=False)")
        if self.translation not in TRANSLATION_MODES:
            raise ValueError(
                f"Expected translation in {TRANSLATION_MODES} (got {self.translation!r})"
            )
        if self.inputs not in INPUT_MODES:
            raise ValueError(f"Expected inputs in {INPUT_MODES} (got {self.inputs!r})")
        if not 0.0 <= self.dropout < 1.0:
            raise ValueError(f"Expected dropout in [0, 1) (got {self.dropout!r})")
        if not isinstance(self.geometric, bool):
            raise ValueError(f"Expected a bool 'geometric' (got {self.geometric!r})")
        if not isinstance(self.geometric_iterations, int) or self.geometric_iterations < 0:
            raise ValueError(f"Expected geometric_iterations >= 0 (got "
                             f"{self.geometric_iterations!r})")
        if not self.geometric_tau > 0:
            raise ValueError(f"Expected geometric_tau > 0 (got {self.geometric_tau!r})")

    @classmethod
    def ablation(cls, name: str, **overrides: Any) -> StrLPoseConfig:
        """The configuration of one row of the paper's ablation table.

        Args:
            name: one of ``"baseline"``, ``"L"``, ``"LP"``, ``"R"``, ``"V"``, ``"LP+R"``,
                ``"LP+V"``, ``"V+W"``, ``"full"``.
            **overrides: other fields (width, depth, translation mode, ...).
        """
        if name not in ABLATIONS:
            raise ValueError(f"Expected an ablation in {tuple(ABLATIONS)} (got {name!r})")
        return cls(**{**ABLATIONS[name], **overrides})

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> StrLPoseConfig:
        """The config of a stored dict; one without ``inputs`` predates the field and was
        trained on the paper's inputs."""
        if isinstance(d, dict) and "inputs" not in d:
            d = {**d, "inputs": "paper"}
        return strict_from_dict(cls, d)


@dataclass
class PoseOutput:
    """Predicted relative pose ``T_0to1`` (maps camera-0 points into camera 1,
    ``X1 = R X0 + t``) of ``B`` pairs.

    Attributes:
        quaternion: unit quaternions ``(w, x, y, z)`` with ``w >= 0``, ``[B, 4]``.
        translation: ``[B, 3]``; a unit direction when the model's ``translation`` is
            ``"direction"``, metric otherwise.
        log_var: predicted log-variance ``log sigma^2`` of the 7 pose components (quaternion
            first), ``[B, 7]``; ``exp(-log_var)`` is the inverse variance of the paper.
    """

    quaternion: Tensor
    translation: Tensor
    log_var: Tensor
    geometric: GeometricOutput | None = None

    @property
    def R(self) -> Tensor:
        """Rotation matrices ``[B, 3, 3]``."""
        return quaternion_to_rotation(self.quaternion)

    @property
    def pose(self) -> Pose:
        return Pose(self.R, self.translation)

    @property
    def T_0to1(self) -> Tensor:
        """Homogeneous ``[B, 4, 4]`` matrices."""
        return self.pose.matrix()

    @property
    def sigma_deg(self) -> Tensor:
        """``[B, 2]``: the RMS rotation and translation-direction angles (degrees) that
        :attr:`log_var` predicts, to first order (the square roots of the traces of
        :func:`~strl_pyg.estimation.pose_fusion.network_covariance`'s blocks). The network's
        own, uncalibrated: :class:`~strl_pyg.inference.PoseEstimator`'s ``regression`` record
        scales it by the checkpoint's calibration."""
        var = torch.exp(self.log_var.double())
        q = torch.nn.functional.normalize(self.quaternion.double(), dim=-1)
        # the rotation block is 4 G^T diag(var_q) G, G's rows orthonormal to q: its trace is
        # 4 sum_i var_i (1 - q_i^2)
        rot = 4.0 * (var[:, :4] * (1.0 - q * q)).sum(-1)
        # the translation block projects diag(var_t) / |t|^2 onto the plane normal to t
        t = self.translation.double()
        tn2 = (t * t).sum(-1).clamp_min(1e-24)
        u = t / tn2.sqrt()[:, None]
        tr = (var[:, 4:] * (1.0 - u * u)).sum(-1) / tn2
        return torch.rad2deg(torch.stack([rot.sqrt(), tr.sqrt()], dim=-1))


#: ``GeometricOutput.status`` codes: the solve's own (``strl_pyg.geometry.essential.OK`` /
#: ``DEGENERATE``) plus this one: the graph was normalised by image size, not by intrinsics, so
#: the weighted solve would give a fundamental matrix and no metric pose.
NO_INTRINSICS = 2


@dataclass
class GeometricOutput:
    """Output of the geometric head (``StrLPoseConfig.geometric``), per node and per pair.

    Node tensors are in the model's node order (``batch`` sorted; within a pair, points first,
    then line endpoints); ``point_logits`` / ``endpoint_logits`` are the same logits in the
    graph's own storage order of each node type (index ``i`` is ``data['point']`` row ``i``).

    Attributes:
        logits: ``[N]`` inlier logits (sigmoid = weight of the node in the solve).
        batch: ``[N]`` pair index of every node.
        coords: ``[N, 4]`` normalised ``(x0, y0, x1, y1)`` of every node.
        point_logits, endpoint_logits: ``[N_point]``, ``[N_endpoint]`` (or ``None``).
        E: ``[B, 3, 3]`` algebraic essential matrices of the weighted solve (unit norm).
        status: ``[B]`` long: 0 ok, 1 degenerate (too few effective matches, rank-deficient),
            :data:`NO_INTRINSICS`.
        R, t: ``[B, 3, 3]``, ``[B, 3]`` pose decomposed from ``E`` (cheirality), float64,
            not differentiable; identity / zero where ``status`` is not 0.
        focal: ``[B]`` mean focal length in pixels of the pair (1 without intrinsics), used to
            express pixel thresholds in normalised units.
    """

    logits: Tensor
    batch: Tensor
    coords: Tensor
    point_logits: Tensor | None
    endpoint_logits: Tensor | None
    E: Tensor
    status: Tensor
    R: Tensor
    t: Tensor
    focal: Tensor

    @property
    def T_0to1(self) -> Tensor:
        return Pose(self.R, self.t).matrix()
