"""SAC update throughput of models/train.py's networks (herbnet112 actor, twin critics, targets,
Adam, entropy temperature) on random batches: updates/s and samples/s at a given batch size.

Usage: python models/bench_sac.py [--batch 256] [--updates 20] [--threads N]
Prints one JSON line (device, batch, updates_per_s, samples_per_s).
"""

import argparse
import json
import time

import torch
import torch.nn.functional as F

import train


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--batch", type=int, default=256)
    ap.add_argument("--updates", type=int, default=20)
    ap.add_argument("--threads", type=int, default=None)
    a = ap.parse_args()
    if a.threads:
        torch.set_num_threads(a.threads)
    dev = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    actor, critic, target = train.Actor().to(dev), train.Critic().to(dev), train.Critic().to(dev)
    log_alpha = torch.zeros((), device=dev, requires_grad=True)
    oa = torch.optim.Adam(actor.parameters(), lr=3e-4)
    oc = torch.optim.Adam(critic.parameters(), lr=3e-4)
    ot = torch.optim.Adam([log_alpha], lr=3e-4)
    b = a.batch
    o = torch.rand(b, *train.POOLED, device=dev)
    o2 = torch.rand(b, *train.POOLED, device=dev)
    act = torch.rand(b, 3, device=dev) * 2 - 1
    r, d = torch.rand(b, device=dev), torch.zeros(b, device=dev)

    def update():
        alpha = log_alpha.exp().detach()
        with torch.no_grad():
            a2, lp2 = actor.sample(o2)
            y = r + 0.99 * (1 - d) * (torch.min(*target(o2, a2)) - alpha * lp2)
        q1, q2 = critic(o, act)
        lc = F.mse_loss(q1, y) + F.mse_loss(q2, y)
        oc.zero_grad(set_to_none=True)
        lc.backward()
        oc.step()
        an, lp = actor.sample(o)
        la = (alpha * lp - torch.min(*critic(o, an))).mean()
        oa.zero_grad(set_to_none=True)
        la.backward()
        oa.step()
        lt = -(log_alpha * (lp.detach() - 3.0)).mean()
        ot.zero_grad(set_to_none=True)
        lt.backward()
        ot.step()
        with torch.no_grad():
            for p, pt in zip(critic.parameters(), target.parameters()):
                pt.mul_(0.995).add_(0.005 * p)

    for _ in range(3):
        update()
    if dev.type == "cuda":
        torch.cuda.synchronize()
    t0 = time.perf_counter()
    for _ in range(a.updates):
        update()
    if dev.type == "cuda":
        torch.cuda.synchronize()
    dt = time.perf_counter() - t0
    print(json.dumps({"device": str(dev), "threads": torch.get_num_threads(), "batch": b,
                      "updates_per_s": round(a.updates / dt, 2), "samples_per_s": round(a.updates * b / dt, 1)}))


if __name__ == "__main__":
    main()
