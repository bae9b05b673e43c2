"""SAC update throughput of models/continuous/train.py's networks (herbnet112 or herblite56 actor, twin critics, targets,
Adam, entropy temperature) on random batches: updates/s and samples/s at a given batch size.

Usage: python models/continuous/bench_sac.py [--batch 256] [--updates 20] [--threads N] [--pool 2|4]
Prints one JSON line (device, batch, updates_per_s, samples_per_s).
"""

import argparse
import json
import time

import torch

import train


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--batch", type=int, default=256)
    ap.add_argument("--updates", type=int, default=20)
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--pool", type=int, default=2, choices=sorted(train.NETS))
    a = ap.parse_args()
    if a.threads:
        torch.set_num_threads(a.threads)
    dev = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    actor, critic, target = (train.Actor(a.pool).to(dev), train.Critic(a.pool).to(dev),
                             train.Critic(a.pool).to(dev))
    log_alpha = torch.zeros((), device=dev, requires_grad=True)
    oa = torch.optim.Adam(actor.parameters(), lr=3e-4)
    oc = torch.optim.Adam(critic.parameters(), lr=3e-4)
    ot = torch.optim.Adam([log_alpha], lr=3e-4)
    b = a.batch
    o = torch.rand(b, *train.pooled_shape(a.pool), device=dev)
    o2 = torch.rand(b, *train.pooled_shape(a.pool), device=dev)
    act = torch.rand(b, 3, device=dev) * 2 - 1
    r, d = torch.rand(b, device=dev), torch.zeros(b, device=dev)
    ea, ev = torch.zeros(b, 3, device=dev), torch.zeros(b, device=dev)  # no expert labels

    def update():
        train.sac_update(actor, critic, target, log_alpha, (oa, oc, ot), (o, act, r, o2, d, ea, ev),
                         0.99, 0.005, -3.0)

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
    print(json.dumps({"device": str(dev), "net": train.NETS[a.pool], "threads": torch.get_num_threads(), "batch": b,
                      "updates_per_s": round(a.updates / dt, 2), "samples_per_s": round(a.updates * b / dt, 1)}))


if __name__ == "__main__":
    main()
