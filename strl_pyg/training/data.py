"""Training data: the dataset factory of a :class:`~strl_pyg.training.config.TrainConfig`,
its checks (sources, channels) and the batch helpers (collation, input statistics); the
per-step resampling and the step batch sampler are in :mod:`strl_pyg.training.sampling`.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import torch
from torch import Tensor
from torch.utils.data import ConcatDataset
from torch_geometric.data import HeteroData
from torch_geometric.loader.dataloader import Collater

from strl_pyg.data import keys as keys_
from strl_pyg.data.transforms import FixedSizeResample, RandomRoll, roll_pose
from strl_pyg.geometry import Pose
from strl_pyg.training.config import TrainConfig
from strl_pyg.training.sampling import _Cycled, _InMemory

__all__ = ["build_datasets", "describe_data", "check_sources", "check_graph_channels",
           "model_input_channels", "unaugmented_poses", "collater", "fit_input_statistics"]


def build_datasets(cfg: TrainConfig, progress: bool = True) -> tuple[Any, Any]:
    """Training and validation datasets of pair graphs (without resampling)."""
    from strl_pyg import datasets as D

    if cfg.dataset == "synthetic" and cfg.scene_mix is not None:
        return _mixed_datasets(cfg, progress)
    if cfg.dataset == "posed":
        return _posed_datasets(cfg, progress)
    if cfg.dataset == "synthetic":
        from strl_pyg.synthetic import SceneConfig

        keep = cfg.model_config().visual == "cnn"
        kinds = cfg.scene_kinds or [SceneConfig().kind]

        # --matches frontend was ignored here (the generator's matches were used silently)
        kw = dict(matches="frontend", cache_dir=cfg.cache_dir) if cfg.matches == "frontend" \
            else {}

        scenes = [SceneConfig(**{**cfg.scene, "kind": kind}) for kind in kinds]

        def part(total: int, base: int) -> ConcatDataset:
            parts = generated_parts(cfg, scenes, total, base, keep, **kw)
            for ds in parts if kw else ():
                ds.build_cache(num_workers=cfg.num_workers, progress=progress)
            return ConcatDataset(parts)

        return part(cfg.train_pairs, cfg.resolved_data_seed * 10_000_000), part(
            cfg.val_pairs, 1_000_000 + cfg.resolved_data_seed * 10_000_000)
    model_cfg = cfg.model_config()
    keep = model_cfg.visual == "cnn"
    # the graphs' channels follow the model's (default: the data's, DATA_CHANNELS): a grey
    # model, e.g. fine-tuning the shipped weights, reads colour data as grey
    grey = model_input_channels(model_cfg, cfg.patch_size) == 1
    common = dict(cache_dir=cfg.cache_dir, patch_size=cfg.patch_size, keep_images=keep,
                  limit=cfg.limit, on_missing="skip", grayscale=grey,
                  frontend_config=frontend_of(cfg))
    if cfg.dataset == "kitti":
        train = D.KITTIOdometry(cfg.data_root, split="train", sequences=cfg.train_sequences,
                                frame_gap=cfg.kitti_k, **common)
        val = D.KITTIOdometry(cfg.data_root, split="test", sequences=cfg.val_sequences,
                              frame_gap=cfg.kitti_k, **common)
    else:
        train = D.DeMoNFolder(cfg.data_root, split="train", **common)
        val = D.DeMoNFolder(cfg.data_root, split="test", **common)
    # before any matching: a run must not train for hours and then have nothing to validate
    check_sources(cfg, train, val)
    for ds in (train, val):
        ds.build_cache(num_workers=cfg.num_workers, progress=progress)
    check_sources(cfg, train, val, matched=True)
    return train, val


def posed_scenes(cfg: TrainConfig) -> tuple[list[str], list[str]]:
    """The training and validation scene names of a ``posed`` run: the config's, or the fixed
    real_scenes split where ``data_root`` holds its scenes. A scene in both lists, an absent
    scene and an empty list are errors naming the flag."""
    from strl_pyg.datasets.posed import REAL_SCENES_SPLIT

    root = Path(cfg.data_root)
    on_disk = sorted(p.name for p in root.iterdir() if p.is_dir()) if root.is_dir() else []
    train, val = cfg.train_scenes, cfg.val_scenes
    if train is None and val is None and set(REAL_SCENES_SPLIT["train"]) <= set(on_disk):
        train, val = list(REAL_SCENES_SPLIT["train"]), list(REAL_SCENES_SPLIT["val"])
    for flag, names in (("--train-scenes", train), ("--val-scenes", val)):
        if not names:
            raise ValueError(f"Expected {flag} with scene folders under '{root}' (got none; "
                             f"on disk: {', '.join(on_disk[:12]) or 'nothing'})")
        missing = [n for n in names if n not in on_disk]
        if missing:
            raise ValueError(f"Expected {flag} scenes under '{root}' (got {', '.join(missing)}, "
                             f"not there; on disk: {', '.join(on_disk[:12]) or 'nothing'})")
    both = sorted(set(train) & set(val))
    if both:
        raise ValueError(f"Expected training and validation scenes apart (got {', '.join(both)} "
                         "in both): validation would measure training photographs")
    return list(train), list(val)


def generated_parts(cfg: TrainConfig, scenes: list, total: int, base: int, keep: bool,
                    **kw: Any) -> list:
    """``total`` generated pairs split as evenly as possible over the scene configurations
    ``scenes``: configuration ``j`` gets the seeds ``base + j * 100_000 + i`` (``kw``: more
    :class:`~strl_pyg.datasets.SyntheticPairs` options, e.g. front-end matches)."""
    from strl_pyg import datasets as D

    sizes = [total // len(scenes) + (j < total % len(scenes)) for j in range(len(scenes))]
    return [D.SyntheticPairs(n, seed=base + j * 100_000, scene_config=sc,
                             patch_size=cfg.patch_size, keep_images=keep, **kw)
            for j, (sc, n) in enumerate(zip(scenes, sizes, strict=True)) if n > 0]


def describe_data(dataset: Any) -> dict[str, int]:
    """Items of ``dataset`` per source, as ``config.json`` records them under ``"data"``: a
    real dataset's subsets (scenes, sequences) by name, ``"generated"`` for generated pairs,
    ``"generated (N distinct, cycled)"`` for a generated share cycled to its size."""
    if isinstance(dataset, _InMemory):
        return describe_data(dataset.base)
    if isinstance(dataset, _Cycled):
        inner = describe_data(dataset.base)
        distinct = sum(inner.values())
        return {f"{'+'.join(inner)} ({distinct} distinct, cycled)": len(dataset)}
    if isinstance(dataset, ConcatDataset):
        out: dict[str, int] = {}
        for part in dataset.datasets:
            for k, v in describe_data(part).items():
                out[k] = out.get(k, 0) + v
        return out
    if hasattr(dataset, "record") and hasattr(dataset, "records"):  # a PairDataset
        out = {}
        for i in range(len(dataset)):
            subset = dataset.record(i).subset
            out[subset] = out.get(subset, 0) + 1
        return out
    name = "generated" if type(dataset).__name__ == "SyntheticPairs" else type(dataset).__name__
    return {name: len(dataset)}


def drop_match_scores(data: HeteroData) -> HeteroData:
    """The graph without the front end's match scores (``score`` of points and endpoints),
    which generated pairs do not have (the model does not read them)."""
    for store in (data[keys_.POINT], data[keys_.ENDPOINT]):
        if keys_.SCORE in store:
            del store[keys_.SCORE]
    return data


def frontend_of(cfg: TrainConfig) -> Any:
    """The front end of a run on photographs: ``cfg.matcher``'s preset, or ``None`` (the
    datasets' default, ``FrontendConfig()``)."""
    if cfg.matcher is None:
        return None
    from strl_pyg.frontend.config import FrontendConfig

    return FrontendConfig.preset(cfg.matcher)


def _posed_datasets(cfg: TrainConfig, progress: bool = True) -> tuple[Any, Any]:
    """Posed photographs (training scenes, pairs by overlap; validation scenes, pairs
    ``(i, i + val_gap)``), with generated pairs mixed into training at ``synthetic_share``."""
    from strl_pyg.datasets.posed import PosedImagePairs, PosedPairOptions

    model_cfg = cfg.model_config()
    keep = model_cfg.visual == "cnn"
    # a model that reads no pixels gets the generated pairs' grey patches too: a mixed batch
    # collates only graphs whose patches have the same channels
    grey = model_input_channels(model_cfg, cfg.patch_size) in (None, 1)
    train_names, val_names = posed_scenes(cfg)
    root = Path(cfg.data_root)
    common = dict(cache_dir=cfg.cache_dir, patch_size=cfg.patch_size, keep_images=keep,
                  grayscale=grey, frontend_config=frontend_of(cfg))
    # generated graphs carry no front-end scores: a mixed batch collates the keys both have
    mixed = dict(transform=drop_match_scores) if cfg.synthetic_share > 0 else {}
    train = PosedImagePairs([root / n for n in train_names], limit=cfg.limit, **mixed,
                            min_points=cfg.posed_min_points, pairs=
                            PosedPairOptions(gaps=tuple(cfg.posed_gaps),
                                             stride=cfg.posed_stride,
                                             max_rotation_deg=cfg.posed_max_rotation,
                                             min_covisible=cfg.posed_min_covisible),
                            **common)
    val = PosedImagePairs([root / n for n in val_names], pairs=PosedPairOptions(
        gaps=(cfg.val_gap,), stride=cfg.val_stride, max_rotation_deg=180.0,
        max_axis_angle_deg=180.0, min_covisible=0.0), **common)
    for role, ds in (("training", train), ("validation", val)):  # before any matching
        if ds.num_pairs == 0:
            raise ValueError(f"Expected {role} pairs from the scenes (got none: "
                             f"{ds.no_pairs_reason()})")
    for ds in (train, val):
        ds.build_cache(num_workers=cfg.num_workers, progress=progress)
    for role, ds in (("training", train), ("validation", val)):
        if len(ds) == 0:
            least = f" with >= {ds.min_points} point matches" if ds.min_points else ""
            raise ValueError(f"Expected {role} pairs the front end can match{least} (got "
                             f"none of {ds.num_pairs}; the cache is '{ds.cache.dir}')")
    if cfg.synthetic_share == 0:
        return train, val
    from strl_pyg.synthetic import SceneConfig

    n_share = round(len(train) * cfg.synthetic_share / (1.0 - cfg.synthetic_share))
    n_gen = n_share if cfg.synthetic_pairs is None else min(cfg.synthetic_pairs, n_share)
    if cfg.scene_mix is not None:
        from strl_pyg.synthetic.distributions import scene_distribution

        scenes = [scene_distribution(cfg.scene_mix)]
    else:
        scenes = [SceneConfig(**{**cfg.scene, "kind": k})
                  for k in (cfg.scene_kinds or [SceneConfig().kind])]
    gen = ConcatDataset(generated_parts(cfg, scenes, n_gen, cfg.resolved_data_seed * 10_000_000,
                                        keep))
    if len(gen) < n_share:
        gen = _Cycled(_InMemory(gen, cfg.in_memory), n_share)
    return ConcatDataset([train, gen]), val


def model_input_channels(model_cfg: Any, patch_size: int) -> int | None:
    """Image channels a model reads (``None``: no visual branch): ``image_channels`` for
    ``visual="cnn"``, else ``patch_features / patch_size**2``."""
    if model_cfg.visual is None:
        return None
    if model_cfg.visual == "cnn":
        return model_cfg.image_channels
    return model_cfg.patch_features // patch_size ** 2


def check_graph_channels(model_cfg: Any, patch_size: int, graph: HeteroData) -> None:
    """``ValueError`` before training when the data's patches (or images) do not have the
    channels the model reads, naming the ``--set`` flags that fit the data."""
    if model_cfg.visual is None:
        return
    store = graph[keys_.POINT]
    if model_cfg.visual == "cnn":
        img = graph[keys_.IMAGE0] if keys_.IMAGE0 in graph else None
        got = None if img is None else int(img.shape[-3])
        want, flag = model_cfg.image_channels, "image_channels"
    else:
        patch = store[keys_.PATCH0] if keys_.PATCH0 in store else None
        got = None if patch is None else int(patch.shape[1])
        want, flag = model_cfg.patch_features, "patch_features"
    if got is not None and got != want:
        c = got // patch_size ** 2 if flag == "patch_features" else got
        raise ValueError(
            f"Expected training graphs with the {want} {flag} the model reads (got {got}: "
            f"{c}-channel images); pass --set patch_features={c * patch_size ** 2} "
            f"--set image_channels={c}, or leave both unset to follow the data")


def _kitti_on_disk(root: Path, camera: str) -> list[str]:
    seq_dir = root / "sequences"
    if not seq_dir.is_dir():
        return []
    return sorted(p.name for p in seq_dir.iterdir() if (p / camera).is_dir())


def check_sources(cfg: TrainConfig, train: Any, val: Any, matched: bool = False) -> None:
    """Raises ``ValueError`` naming what is missing, and the flag that fixes it, when the
    training or validation set of a real dataset holds no pair (sequences absent, no pairs
    among the frames on disk, or, with ``matched``, every pair failed matching); warns when
    KITTI validation sequences are also training sequences."""
    flags = {"train": ("--train-sequences", cfg.train_sequences),
             "validation": ("--val-sequences", cfg.val_sequences)}
    for role, ds in (("train", train), ("validation", val)):
        if (len(ds) if matched else ds.num_pairs) > 0:  # num_pairs: no cache touched
            continue
        if matched:
            raise ValueError(
                f"Expected {role} pairs that the front end can match (got none: all "
                f"{ds.num_pairs} gave no matches; markers in '{ds.cache.dir}')")
        if cfg.dataset == "kitti":
            on_disk = _kitti_on_disk(Path(cfg.data_root), ds.camera)
            asked = list(ds.sequences) + list(ds.missing_sequences)
            why = (f"sequences {', '.join(ds.missing_sequences)} have no '{ds.camera}' folder "
                   f"under '{Path(cfg.data_root) / 'sequences'}'" if ds.missing_sequences
                   else f"no frames i, i + {cfg.kitti_k} both with images")
            flag, given = flags[role]
            default = "" if given else " (the standard split)"
            raise ValueError(
                f"Expected {role} pairs from KITTI sequences {', '.join(asked)}{default} (got "
                f"none: {why}); pass {flag} with sequences that exist (here: "
                f"{', '.join(on_disk) or 'none'}), e.g. {flag} {on_disk[-1] if on_disk else 'NN'}")
        split = ds.split
        why = (f"{len(ds.missing_sequences)} listed sequences absent, e.g. "
               f"{ds.missing_sequences[:3]}" if ds.missing_sequences else "no sequences")
        raise ValueError(f"Expected DeMoN {role} pairs under '{Path(cfg.data_root) / split}' "
                         f"(got none: {why})")
    if cfg.dataset == "kitti" and not matched:
        both = sorted(set(train.sequences) & set(val.sequences))
        if both:
            warnings.warn(f"KITTI sequences {', '.join(both)} are in both the training and the "
                          "validation set: validation measures training pairs; pass other "
                          "--val-sequences for a held-out figure", UserWarning, stacklevel=3)


def _mixed_datasets(cfg: TrainConfig, progress: bool = True) -> tuple[Any, Any]:
    """Training / validation sets drawn from a named scene distribution
    (:func:`strl_pyg.synthetic.scene_distribution`: one scene configuration per seed)."""
    from strl_pyg import datasets as D
    from strl_pyg.synthetic.distributions import DISTRIBUTIONS, scene_distribution

    if cfg.scene_mix not in DISTRIBUTIONS:
        raise ValueError(f"Expected scene_mix in {tuple(DISTRIBUTIONS)} (got {cfg.scene_mix!r})")
    dist = scene_distribution(cfg.scene_mix)
    keep = cfg.model_config().visual == "cnn"
    if keep and len(dist.sizes) > 1:  # before any matching: the batch could not be collated
        raise ValueError(f"Expected a scene mix of one image size for a model with "
                         f"visual='cnn' (its CNN batches whole images; e.g. --scene-mix "
                         f"lines_small) (got '{cfg.scene_mix}' with sizes {list(dist.sizes)})")
    kw = dict(matches="frontend", cache_dir=cfg.cache_dir) if cfg.matches == "frontend" else {}
    sets = []
    for n, base in ((cfg.train_pairs, cfg.resolved_data_seed * 10_000_000),
                    (cfg.val_pairs, 1_000_000 + cfg.resolved_data_seed * 10_000_000)):
        ds = D.SyntheticPairs(n, seed=base, scene_config=dist, patch_size=cfg.patch_size,
                              keep_images=keep, **kw)
        if kw:
            ds.build_cache(num_workers=cfg.num_workers, progress=progress)
        sets.append(ds)
    return sets[0], sets[1]


def unaugmented_poses(batch: HeteroData) -> Tensor:
    """Ground-truth poses with the roll and swap augmentations undone (the trivial predictor
    is the mean pose of the data as it comes, not of the augmented data)."""
    T = batch[keys_.T_0TO1].detach()
    if keys_.ROLL in batch:  # applied last (ResampledPairs), undone first
        T = roll_pose(T, -batch[keys_.ROLL].reshape(-1))
    if keys_.SWAPPED not in batch:
        return T
    swapped = batch[keys_.SWAPPED].bool()
    T = T.clone()
    T[swapped] = Pose.from_matrix(T[swapped]).inv().matrix().to(T)
    return T


def collater(model_cfg: Any):
    """PyG's collater; images of different sizes (a model with ``visual='cnn'`` batches whole
    images) are a one-line ``ValueError`` instead of torch's ``torch.cat`` error."""
    base = Collater(None)

    def collate(items):
        try:
            return base(items)
        except RuntimeError as err:
            if model_cfg.visual != "cnn" or "Sizes of tensors must match" not in str(err):
                raise
            sizes = sorted({tuple(getattr(d, keys_.IMAGE0).shape[-2:]) for d in items
                            if keys_.IMAGE0 in d})
            raise ValueError(f"Expected one image size per batch for a model with "
                             f"visual='cnn' (its CNN batches whole images) (got sizes "
                             f"{sizes}); train on one size or use visual='pixel'") from None

    return collate


def fit_input_statistics(model: torch.nn.Module, dataset: Any, symmetric: bool,
                         max_pairs: int = 128, roll: float = 0.0,
                         resample: tuple[int, int] | None = None) -> None:
    """Sets the flow inputs' standardisation (``model.sce``) from the node coordinates of the
    first ``max_pairs`` training pairs (with their swapped copies when ``symmetric``, and each
    pair rolled as training rolls it (:class:`~strl_pyg.data.RandomRoll`, a fixed seed) when
    ``roll`` > 0); they are buffers, so the checkpoint keeps them. With ``inputs="parallax"``
    each pair is first resampled to ``resample = (points, lines)`` as training resamples it
    (a neighbour's distance depends on the density)."""
    roller = RandomRoll(roll, seed=0) if roll > 0 else None
    parallax = model.config.inputs == "parallax"
    # the parallax fit reads the nodes the model reads, at the density it trains on (its
    # neighbours are those nodes); the flow inputs' fit keeps reading every node of every
    # pair, as the runs already trained did
    types = (keys_.POINT, keys_.ENDPOINT) if not parallax or model.config.use_lines \
        else (keys_.POINT,)
    coords, batch = [], []
    for i in range(min(max_pairs, len(dataset))):
        g = dataset[i]
        if parallax and resample is not None:
            g = FixedSizeResample(*resample, seed=i)(g)
        if roller is not None:
            g = roller(g)
        for t in types:
            if t in g.node_types and keys_.POS0 in g[t] and g[t][keys_.POS0].shape[0]:
                coords.append(torch.cat([g[t][keys_.POS0], g[t][keys_.POS1]], -1).float())
                batch.append(torch.full((coords[-1].shape[0],), i, dtype=torch.long))
    if coords:
        model.sce.fit_standardisation(torch.cat(coords).cpu(), symmetric=symmetric,
                                      batch=torch.cat(batch))
        model.sce.to(next(model.parameters()).device)
