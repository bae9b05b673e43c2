#!/usr/bin/env python3
"""Behaviour cloning of the humans' placements: the BC-MSE and BC-MDN rows of Table I.

    python training/bc.py --out runs/bc [--minutes 3] [--threads 2] [--seed 0]

Data: ``herb_sim.human_demonstrations()``: for every object of the 263 BoxED sessions, the
observation of the humans' own scene before it (earlier objects at their recorded poses, the
shared layout, pooled 4 x 4 and stored as uint8) and the human's planar placement as the
contract's action (x / BOX_HALF_X, y / BOX_HALF_Y, theta / pi).

Targets, as in the paper: x and y in (-1, 1) and theta as (sin, cos).

- **BC-MSE**: the herblite56 network (the first, continuous-action recipe's extractor and
  MLP, defined below) regressing (x, y, sin, cos) with a squared-error loss; x and y through
  tanh.
- **BC-MDN**: the same network with a mixture density head (Bishop 1994): K = 5 Gaussian
  components with diagonal covariance over (x, y, sin, cos), trained by negative
  log-likelihood. Deployed action: the mean of the most probable component.

**Held out by participant (two folds).** Sessions are split by the parity of their
participant number (``p<N>``): the model written as ``bc-<kind>-heldout-even.onnx`` is trained
on odd participants only and scores the even ones in Table I, and the other way round, so no
row scores a participant its model was trained on. Within a fold, 10 % of the training
participants are kept apart for choosing the epoch (lowest validation loss); BoxED's scoring
participants are never used for any choice.

Export: ``obs [1, 2, 224, 224] -> action [1, 3]``, the continuous contract herbd and
``herb-sim eval`` load (``herb_decide::load_policy``); theta = atan2(sin, cos) / pi. Each model
is checked by the ONNX checker, the I/O contract and onnxruntime against PyTorch (1e-4) on
real observations before it is written; those observations and PyTorch's actions are saved
beside it (``.parity.{bin,json}``) for the tract parity test. Evaluate with
``herb-sim eval --method bc-mse --method bc-mdn --bc-models <out>``.
"""

import argparse
import json
import math
import os
import time
import warnings

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

import herb_sim

# The observation contract herbd and herb-sim eval load (herb_decide::load_policy).
CONTRACT = dict(input=herb_sim.INPUT_NAME, input_shape=list(herb_sim.MODEL_INPUT_SHAPE),
                output=herb_sim.OUTPUT_NAME, output_shape=list(herb_sim.MODEL_OUTPUT_SHAPE))


def extractor(pool):
    """Convolutional features of a pooled observation; returns (module, feature count). The
    first recipe's SAC extractors (pool 2: herbnet112, pool 4: herblite56), layer for layer."""
    if pool == 2:
        convs = [nn.Conv2d(2, 16, 8, stride=4), nn.ReLU(), nn.Conv2d(16, 32, 4, stride=2), nn.ReLU()]
        side = 10
        last = nn.Conv2d(32, 32, 3, stride=1)
    else:
        convs = [nn.Conv2d(2, 16, 5, stride=2), nn.ReLU(), nn.Conv2d(16, 32, 3, stride=2), nn.ReLU()]
        side = 5
        last = nn.Conv2d(32, 32, 3, stride=2)
    return nn.Sequential(*convs, last, nn.ReLU(), nn.Flatten()), 32 * side * side


def mlp(n_in, n_out):
    """The first recipe's MLP: three hidden layers of 256."""
    return nn.Sequential(
        nn.Linear(n_in, 256), nn.ReLU(),
        nn.Linear(256, 256), nn.ReLU(),
        nn.Linear(256, 256), nn.ReLU(),
        nn.Linear(256, n_out),
    )


POOL = 4  # herblite56
K = 5  # MDN components
KINDS = ("mse", "mdn")


class BcNet(nn.Module):
    """herblite56 features and MLP; an MSE head (4 values) or an MDN head (K x (1 + 4 + 4))."""

    def __init__(self, kind):
        super().__init__()
        self.kind = kind
        self.features, n = extractor(POOL)
        self.body = mlp(n, 4 if kind == "mse" else K * 9)

    def forward(self, x):
        """Pooled observation -> MSE: (x, y, sin, cos); MDN: logits [B, K], means [B, K, 4],
        log-stds [B, K, 4]."""
        out = self.body(self.features(x))
        if self.kind == "mse":
            return torch.cat([torch.tanh(out[:, :2]), out[:, 2:]], -1)
        out = out.view(-1, K, 9)
        logits, mu, log_std = out[..., 0], out[..., 1:5], out[..., 5:9].clamp(-7.0, 2.0)
        mu = torch.cat([torch.tanh(mu[..., :2]), mu[..., 2:]], -1)
        return logits, mu, log_std

    def loss(self, x, y):
        """Mean loss of a batch: squared error, or the mixture's negative log-likelihood."""
        if self.kind == "mse":
            return F.mse_loss(self(x), y)
        logits, mu, log_std = self(x)
        z = (y.unsqueeze(1) - mu) / log_std.exp()
        comp = (-0.5 * z * z - log_std - 0.5 * math.log(2 * math.pi)).sum(-1)
        return -(torch.logsumexp(F.log_softmax(logits, -1) + comp, -1)).mean()

    def point(self, x):
        """The deployed (x, y, sin, cos): the MSE output, or the most probable component's mean."""
        if self.kind == "mse":
            return self(x)
        logits, mu, _ = self(x)
        k = logits.argmax(-1)
        return mu[torch.arange(mu.shape[0]), k]


class Deployed(nn.Module):
    """What ships: full observation in, the contract's action (x, y, theta / pi) out."""

    def __init__(self, net):
        super().__init__()
        self.net = net

    def forward(self, obs):
        p = self.net.point(F.avg_pool2d(obs, POOL))
        theta = torch.atan2(p[:, 2], p[:, 3]) / math.pi
        return torch.cat([p[:, :2], theta.unsqueeze(-1)], -1)


def targets(actions):
    """Contract actions [N, 3] -> (x, y, sin theta, cos theta)."""
    th = actions[:, 2] * math.pi
    return np.stack([actions[:, 0], actions[:, 1], np.sin(th), np.cos(th)], -1).astype(np.float32)


def train(kind, obs, y, val_obs, val_y, minutes, seed, log):
    """Trains one model for `minutes` of wall time; returns the state of the epoch with the lowest
    validation loss and a summary."""
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    net = BcNet(kind)
    opt = torch.optim.Adam(net.parameters(), lr=3e-4)
    to_t = lambda a: torch.as_tensor(a.astype(np.float32) / 255.0)
    xv, yv = to_t(val_obs), torch.as_tensor(val_y)
    best = (math.inf, None, 0)
    t0, epoch, updates = time.time(), 0, 0
    while time.time() - t0 < minutes * 60:
        net.train()
        perm = rng.permutation(len(obs))
        for i in range(0, len(perm) - 63, 64):
            idx = perm[i:i + 64]
            loss = net.loss(to_t(obs[idx]), torch.as_tensor(y[idx]))
            opt.zero_grad()
            loss.backward()
            opt.step()
            updates += 1
        epoch += 1
        net.eval()
        with torch.no_grad():
            v = float(net.loss(xv, yv))
        if v < best[0]:
            best = (v, {k: t.clone() for k, t in net.state_dict().items()}, epoch)
        log(f"  {kind} epoch {epoch}: train loss {loss.item():.4f}, validation {v:.4f}")
    net.load_state_dict(best[1])
    net.eval()
    return net, dict(epochs=epoch, updates=updates, best_epoch=best[2], val_loss=best[0],
                     seconds=round(time.time() - t0, 1))


def export(net, path, parity_obs):
    """Writes `path` only if the ONNX checker, the contract and onnxruntime (against PyTorch,
    1e-4) pass on `parity_obs` ([n, 2, 224, 224] float32); saves them and PyTorch's actions beside
    it for the tract parity test."""
    import onnx
    import onnxruntime as ort

    model = Deployed(net).eval()
    tmp = path + ".tmp"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(model, torch.zeros(*CONTRACT["input_shape"]), tmp,
                          input_names=[CONTRACT["input"]], output_names=[CONTRACT["output"]],
                          opset_version=17, dynamo=False)
    m = onnx.load(tmp)
    onnx.checker.check_model(m)
    dims = lambda v: [d.dim_value for d in v.type.tensor_type.shape.dim]
    ins, outs = m.graph.input, m.graph.output
    if not (len(ins) == 1 and ins[0].name == CONTRACT["input"] and dims(ins[0]) == CONTRACT["input_shape"]
            and len(outs) == 1 and outs[0].name == CONTRACT["output"]
            and dims(outs[0]) == CONTRACT["output_shape"]):
        os.remove(tmp)
        raise RuntimeError(f"{path}: exported model breaks the I/O contract")
    sess = ort.InferenceSession(tmp, providers=["CPUExecutionProvider"])
    expect = []
    for k in range(len(parity_obs)):
        x = parity_obs[k:k + 1]
        with torch.no_grad():
            t = model(torch.as_tensor(x)).numpy()
        o = sess.run(None, {CONTRACT["input"]: x})[0]
        if not np.allclose(t, o, atol=1e-4):
            os.remove(tmp)
            raise RuntimeError(f"{path}: onnxruntime differs from PyTorch: {t} vs {o}")
        expect.append(t[0].tolist())
    os.replace(tmp, path)
    stem = path[:-len(".onnx")]
    parity_obs.astype("<f4").tofile(stem + ".parity.bin")
    with open(stem + ".parity.json", "w") as f:
        json.dump({"samples": len(expect), "shape": CONTRACT["input_shape"], "actions": expect}, f)


def unpool(obs_u8):
    """Pooled uint8 observations -> full-resolution float32 (each pooled value repeated): real
    scenes at the contract's input size, for the parity samples."""
    x = obs_u8.astype(np.float32) / 255.0
    return np.ascontiguousarray(x.repeat(POOL, axis=2).repeat(POOL, axis=3))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, help="folder for the four models and the log")
    ap.add_argument("--minutes", type=float, default=3.0, help="wall time per model")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--boxed", default=None, help="BoxED folder (default: HERB_BOXED or ../shared/boxed)")
    ap.add_argument("--in-sample", action="store_true",
                    help="a diagnostic, not Table I's rows: train each kind on every participant "
                         "(10 %% kept apart for the epoch) and write bc-<kind>-insample.onnx; "
                         "scoring BoxED with it is in-sample, as a paper-style 85/15 split is")
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    os.makedirs(a.out, exist_ok=True)
    logf = open(os.path.join(a.out, "bc.log"), "a")

    def log(msg):
        print(msg, flush=True)
        logf.write(msg + "\n")
        logf.flush()

    t0 = time.time()
    d = herb_sim.human_demonstrations(boxed=a.boxed, pool=POOL)
    for s, why in d["skipped"]:
        log(f"skipped session {s}: {why}")
    obs, acts, part = d["obs"], d["actions"], d["participant"]
    y = targets(acts)
    log(f"{len(obs)} demonstrations from {len(d['names'])} sessions in {time.time() - t0:.1f} s")
    cards = {}
    if a.in_sample:
        parts = np.unique(part)
        rng = np.random.default_rng(a.seed)
        val_parts = rng.choice(parts, size=max(1, len(parts) // 10), replace=False)
        va = np.isin(part, val_parts)
        for kind in KINDS:
            name = f"bc-{kind}-insample"
            log(f"{name}: {(~va).sum()} training and {va.sum()} validation demonstrations")
            net, card = train(kind, obs[~va], y[~va], obs[va], y[va], a.minutes, a.seed, log)
            export(net, os.path.join(a.out, name + ".onnx"), unpool(obs[[0, 10]]))
            card.update(trained_on="all participants but the validation ones", seed=a.seed,
                        threads=a.threads)
            cards[name] = card
            log(f"{name}: {card}")
        with open(os.path.join(a.out, "bc-insample-cards.json"), "w") as f:
            json.dump(cards, f, indent=1)
        log(f"done in {(time.time() - t0) / 60:.1f} min")
        return
    for heldout, parity in (("even", 0), ("odd", 1)):
        train_parts = np.unique(part[part % 2 != parity])
        rng = np.random.default_rng(a.seed)
        val_parts = rng.choice(train_parts, size=max(1, len(train_parts) // 10), replace=False)
        tr = (part % 2 != parity) & ~np.isin(part, val_parts)
        va = np.isin(part, val_parts)
        for kind in KINDS:
            name = f"bc-{kind}-heldout-{heldout}"
            log(f"{name}: {tr.sum()} training and {va.sum()} validation demonstrations "
                f"({len(train_parts) - len(val_parts)} and {len(val_parts)} participants)")
            net, card = train(kind, obs[tr], y[tr], obs[va], y[va], a.minutes, a.seed, log)
            # Parity samples: two scenes of the held-out participants (never trained on).
            held = np.flatnonzero(part % 2 == parity)[[0, 10]]
            export(net, os.path.join(a.out, name + ".onnx"), unpool(obs[held]))
            card.update(trained_on=f"{'odd' if parity == 0 else 'even'} participants",
                        scores=f"{heldout} participants", seed=a.seed, threads=a.threads)
            cards[name] = card
            log(f"{name}: {card}")
    with open(os.path.join(a.out, "bc-cards.json"), "w") as f:
        json.dump(cards, f, indent=1)
    log(f"done in {(time.time() - t0) / 60:.1f} min")


if __name__ == "__main__":
    main()
