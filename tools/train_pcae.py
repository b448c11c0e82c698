#!/usr/bin/env python
"""Trains the point-cloud autoencoder (PCAE) on generated partial views and ships it.

docs/method.md section 3; thesis 3.5 and 6.4. The thesis trained on ShapeNet for
350 epochs; here the data are procedurally generated, skill-agnostic shapes
seen by a simulated Kinect-like depth camera (drake_skill/shapes.py).

Data: every epoch draws ``--clouds-per-epoch`` NEW clouds from the training
stream (cloud i of the stream uses ``np.random.default_rng([seed, i])``), so
no cloud is seen twice and the encoder never overfits a fixed set. The
held-out set uses a different seed (``--heldout-seed``).

Optimisation (thesis 3.5): Chamfer loss on normalised clouds (the thesis'
EMD is too slow on a CPU; Chamfer is the accepted stand-in, docs/method.md 3),
Adam with lr 5e-4, batch 16.

Weight decay: the thesis lists L2 regularisation with lambda = 1e-3, the value
of the ``weight_decay=0.001`` argument in Achlioptas et al.'s released code
(optas/latent_3d_points, src/encoders_decoders.py). There it is inert: the
layers are built with ``regularizer=None`` and ae_templates.py never sets one,
so the reference PCAE trains with no weight decay. On this project's CPU
budget, 1e-3 (Adam-coupled L2 on the Linear weights) held the reconstructions
at a blob: training Chamfer 0.025 (normalised) after 18 epochs, held-out
1226 mm^2 Chamfer and 104 mm EMD, against 0.020 after 5 epochs without it.
The default is therefore 0 (the reference behaviour); ``--weight-decay 1e-3``
gives the thesis' literal setting.

Deterministic for a given seed, thread count and CPU: weights are initialised
from ``torch.manual_seed(seed)``, the batch order of epoch e from a generator
seeded with ``seed * 1000 + e``. A checkpoint is written after every epoch to
``--work``; rerunning the same command resumes from it.

Outputs: ``<out>/pcae.safetensors`` (weights) and ``<out>/pcae.json`` (card:
data recipe, seeds, sizes, epochs, wall time, held-out Chamfer and EMD, input
normalisation).

Usage: ``python tools/train_pcae.py --out models/`` (defaults reproduce the
shipped model; about 20 minutes of training on 2 CPU threads shared with other
work, 12 alone, plus 2-3 minutes of evaluation). ``--smoke`` runs a tiny
configuration in about a minute.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np
import torch

from drake_skill.perception import pcae
from drake_skill.perception import shapes
from drake_skill.fileio import atomic_write_bytes, atomic_write_json


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", type=Path, default=Path("models"), help="folder for pcae.safetensors and pcae.json")
    p.add_argument("--work", type=Path, default=Path("build/pcae_train"), help="checkpoint folder (resumed if present)")
    p.add_argument("--seed", type=int, default=2024, help="seed of the training stream and of the weights")
    p.add_argument("--heldout-seed", type=int, default=7, help="seed of the held-out clouds")
    p.add_argument("--epochs", type=int, default=18)
    p.add_argument("--clouds-per-epoch", type=int, default=2000)
    p.add_argument("--batch-size", type=int, default=16)
    p.add_argument("--lr", type=float, default=5e-4)
    p.add_argument("--weight-decay", type=float, default=0.0,
                   help="L2 on Linear weights (Adam-coupled); see the docstring")
    p.add_argument("--heldout", type=int, default=256, help="held-out clouds for Chamfer")
    p.add_argument("--emd-clouds", type=int, default=64,
                   help="held-out clouds (first ones) for exact EMD on all 2048 points")
    p.add_argument("--val", type=int, default=64, help="held-out clouds evaluated after every epoch")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--smoke", action="store_true", help="tiny run (about a minute) into build/pcae_smoke")
    p.add_argument("--fresh", action="store_true", help="ignore an existing checkpoint")
    args = p.parse_args(argv)
    if args.smoke:
        args.epochs, args.clouds_per_epoch, args.heldout, args.emd_clouds, args.val = 3, 160, 32, 4, 32
        if args.work == Path("build/pcae_train"):
            args.work = Path("build/pcae_smoke")
        if args.out == Path("models"):
            args.out = Path("build/pcae_smoke/out")
    return args


RECIPE_KEYS = ("seed", "heldout_seed", "epochs", "clouds_per_epoch", "batch_size", "lr", "weight_decay", "threads")


def recipe(args) -> dict:
    return {k: getattr(args, k) for k in RECIPE_KEYS}


def recipe_hash(args) -> str:
    r = {k: v for k, v in recipe(args).items() if k != "epochs"}  # more epochs may extend a run
    return hashlib.sha256(json.dumps(r, sort_keys=True).encode()).hexdigest()[:16]


# --------------------------------------------------------------------------- checkpoint


def save_checkpoint(path: Path, model, opt, epoch: int, history: list, wall_s: float, rhash: str) -> None:
    from safetensors.torch import save

    tensors = {f"model.{k}": v.detach().contiguous() for k, v in model.state_dict().items()}
    state = opt.state_dict()
    for pid, st in state["state"].items():
        for k, v in st.items():
            t = v if isinstance(v, torch.Tensor) else torch.tensor(v)
            tensors[f"opt.{pid}.{k}"] = t.detach().contiguous().reshape(t.shape)
    meta = {"epoch": str(epoch), "history": json.dumps(history), "wall_s": repr(wall_s), "recipe_hash": rhash}
    atomic_write_bytes(path, save(tensors, metadata=meta))


def load_checkpoint(path: Path, model, opt, rhash: str):
    """Returns (epoch, history, wall_s) or None when there is no usable checkpoint."""
    from safetensors import safe_open

    if not path.is_file():
        return None
    with safe_open(str(path), framework="pt") as f:
        meta = f.metadata()
        if meta.get("recipe_hash") != rhash:
            print(f"{path}: checkpoint from another recipe; starting fresh", flush=True)
            return None
        tensors = {k: f.get_tensor(k) for k in f.keys()}
    model.load_state_dict({k[6:]: v for k, v in tensors.items() if k.startswith("model.")})
    state = opt.state_dict()
    for pid in range(sum(len(g["params"]) for g in state["param_groups"])):
        st = {k.split(".", 2)[2]: v for k, v in tensors.items() if k.startswith(f"opt.{pid}.")}
        if st:
            state["state"][pid] = st
    opt.load_state_dict(state)
    return int(meta["epoch"]), json.loads(meta["history"]), float(meta["wall_s"])


# --------------------------------------------------------------------------- eval


def chamfer_m2(model, clouds: np.ndarray, batch: int = 32) -> np.ndarray:
    """Per-cloud Chamfer (m^2) between clouds (K, N, 3) in metres and their reconstructions."""
    model.eval()
    out = []
    with torch.inference_mode():
        for i in range(0, len(clouds), batch):
            x = pcae.normalize_points(torch.from_numpy(clouds[i : i + batch]))
            rec, _ = model(x)
            out.append(pcae.chamfer_distance(rec, x).numpy() * pcae.NORMALIZATION_SCALE_M**2)
    return np.concatenate(out)


def emd_m(model, clouds: np.ndarray) -> np.ndarray:
    """Per-cloud exact EMD (m, mean matched distance over all N points) between clouds and reconstructions."""
    rec = model.reconstruct_points(clouds)
    return np.array([pcae.earth_movers_distance(a, b) for a, b in zip(clouds, rec)])


# --------------------------------------------------------------------------- main


def main(argv=None) -> int:
    from tqdm import tqdm

    args = parse_args(argv)
    torch.set_num_threads(args.threads)
    args.work.mkdir(parents=True, exist_ok=True)
    ckpt = args.work / "checkpoint.safetensors"
    cfg = shapes.CloudConfig()
    rhash = recipe_hash(args)

    t_start = time.perf_counter()
    print(f"held-out clouds: {args.heldout} (seed {args.heldout_seed})", flush=True)
    heldout, heldout_kinds = shapes.generate_clouds(args.heldout, args.heldout_seed, cfg, progress=True)
    val = heldout[: args.val]

    torch.manual_seed(args.seed)
    model = pcae.PointCloudAutoencoder()
    opt = torch.optim.Adam(pcae.weight_decay_groups(model, args.weight_decay), lr=args.lr)
    start_epoch, history, wall_before = 0, [], 0.0
    if not args.fresh:
        resumed = load_checkpoint(ckpt, model, opt, rhash)
        if resumed is not None:
            start_epoch, history, wall_before = resumed
            print(f"resumed from {ckpt} after epoch {start_epoch}", flush=True)

    for epoch in range(start_epoch, args.epochs):
        t0 = time.perf_counter()
        clouds, _ = shapes.generate_clouds(args.clouds_per_epoch, args.seed, cfg, start=epoch * args.clouds_per_epoch)
        t_gen = time.perf_counter() - t0
        x_all = pcae.normalize_points(torch.from_numpy(clouds))
        g = torch.Generator().manual_seed(args.seed * 1000 + epoch)
        order = torch.randperm(len(x_all), generator=g)
        model.train()
        losses = []
        bar = tqdm(range(0, len(order), args.batch_size), desc=f"epoch {epoch + 1}/{args.epochs}", unit="batch",
                   mininterval=10)
        for i in bar:
            x = x_all[order[i : i + args.batch_size]]
            rec, _ = model(x)
            loss = pcae.chamfer_distance(rec, x).mean()
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            losses.append(loss.item())
            bar.set_postfix(chamfer=f"{np.mean(losses[-20:]):.5f}", refresh=False)
        bar.close()
        val_cd = float(chamfer_m2(model, val).mean())
        epoch_s = time.perf_counter() - t0
        history.append({"epoch": epoch + 1, "train_chamfer_norm": float(np.mean(losses)), "val_chamfer_m2": val_cd,
                        "seconds": epoch_s, "datagen_seconds": t_gen})
        wall_before += epoch_s
        save_checkpoint(ckpt, model, opt, epoch + 1, history, wall_before, rhash)
        print(f"epoch {epoch + 1}: train Chamfer {np.mean(losses):.5f} (normalised), "
              f"held-out {val_cd * 1e6:.1f} mm^2, {epoch_s:.0f} s", flush=True)

    # ---- final evaluation on the held-out set
    model.eval()
    t0 = time.perf_counter()
    cd = chamfer_m2(model, heldout)
    emd = emd_m(model, heldout[: args.emd_clouds])
    eval_s = time.perf_counter() - t0
    per_kind = {k: float(cd[[i for i, kk in enumerate(heldout_kinds) if kk == k]].mean())
                for k in sorted(set(heldout_kinds))}
    card = {
        "model": "PCAE (Achlioptas et al. 2017; thesis 3.5): encoder per-point MLP 3-64-128-128-256-128 "
                 "(Linear+BatchNorm+ReLU), max-pool -> 128; decoder FC 128-256-256-6144 (ReLU except output)",
        "weights": "pcae.safetensors",
        "n_points": pcae.N_POINTS,
        "code_size": pcae.CODE_SIZE,
        "input_normalisation": {
            "frame": "world frame, z up (metres)",
            "centre": "centre of the cloud's axis-aligned bounding box",
            "scale_m": pcae.NORMALIZATION_SCALE_M,
            "formula": "x_norm = (p - 0.5 (min p + max p)) / scale_m; fixed scale, no per-cloud scaling, "
                       "so object size and state (lid, drawer) stay in the input",
        },
        "data": {
            "generator": "drake_skill.perception.shapes.generate_clouds (open3d RaycastingScene)",
            "shape_kinds": dict(zip(shapes.SHAPE_KINDS, shapes.SHAPE_WEIGHTS)),
            "camera": dataclasses.asdict(cfg.camera),
            "view": dataclasses.asdict(cfg.view),
            "table_cut_probability": cfg.table_cut_probability,
            "table_cut_max_m": cfg.table_cut_max_m,
            "train_stream": f"cloud i uses np.random.default_rng([{args.seed}, i]); "
                            f"epoch e uses clouds e*{args.clouds_per_epoch} .. (e+1)*{args.clouds_per_epoch}-1 "
                            "(every cloud seen once)",
            "train_clouds_total": args.epochs * args.clouds_per_epoch,
            "heldout_clouds": args.heldout,
            "heldout_seed": args.heldout_seed,
        },
        "training": {
            **recipe(args),
            "loss": "Chamfer (mean squared nearest-neighbour distance, both directions) on normalised clouds",
            "optimizer": "Adam; L2 weight decay (weight_decay, Adam-coupled) on Linear weight matrices only",
            "weight_decay_note": "thesis 3.5 lists 1e-3, but Achlioptas et al.'s reference code builds its layers "
                                 "with regularizer=None, so no decay is applied there; 1e-3 stalled training "
                                 "on this budget (see tools/train_pcae.py)",
            "wall_time_s": wall_before,
            "history": history,
            "torch": torch.__version__,
            "platform": platform.processor() or platform.machine(),
        },
        "heldout": {
            "chamfer_m2_mean": float(cd.mean()),
            "chamfer_m2_median": float(np.median(cd)),
            "chamfer_m2_p90": float(np.quantile(cd, 0.9)),
            "chamfer_m2_per_kind": per_kind,
            "chamfer_bound_m2": float(1.5 * cd.mean()),
            "chamfer_bound_note": "tests require the mean Chamfer of freshly generated held-out clouds "
                                  "to be below this (1.5 x held-out mean)",
            "emd_m_mean": float(emd.mean()),
            "emd_m_median": float(np.median(emd)),
            "emd_clouds": int(len(emd)),
            "emd_note": "exact EMD (scipy linear_sum_assignment) on all 2048 points, "
                        "mean matched distance (thesis Eq. 3.32 / N), first emd_clouds held-out clouds",
            "eval_seconds": eval_s,
        },
    }
    out_w = args.out / "pcae.safetensors"
    pcae.save_pcae(model, out_w, metadata={"seed": args.seed, "card": "pcae.json"})
    card["encode_ms_per_frame"] = pcae.time_encode(30, weights=out_w)
    card["total_script_wall_s"] = time.perf_counter() - t_start
    atomic_write_json(args.out / "pcae.json", card)
    print("\nheld-out Chamfer: mean {:.1f} mm^2, median {:.1f} mm^2;  EMD: mean {:.2f} mm ({} clouds)".format(
        cd.mean() * 1e6, np.median(cd) * 1e6, emd.mean() * 1e3, len(emd)))
    for k, v in per_kind.items():
        print(f"  {k:12s} {v * 1e6:8.1f} mm^2")
    print(f"encode: {card['encode_ms_per_frame']:.2f} ms/frame (1 thread)")
    print(f"wrote {out_w}\nwrote {args.out / 'pcae.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
