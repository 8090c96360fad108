"""Diffusion-AC training throughput on CPU: environment steps/s with batched diffusion action
selection (T reverse steps per decision), Algorithm-1 updates/s, and the combined rate at the
default ratio of one update per ``update_every`` transitions.

Run: python benchmarks/train_throughput.py [--n-envs 32] [--seconds 10] [--threads 1]
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np
import torch

from cdr_bench.rl.curriculum import Curriculum, CurriculumEnv
from cdr_bench.rl.offpolicy import collect
from cdr_bench.rl.replay import Replay, ReplayConfig
from cdr_bench.rl.train_diffusion_ac import Args, build


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--n-envs", type=int, default=32)
    ap.add_argument("--seconds", type=float, default=10.0, help="duration of each measurement")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--stage", type=int, default=12, help="curriculum stage to step")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    a = Args(n_envs=args.n_envs)
    env = CurriculumEnv(
        a.n_envs, seed=0, curriculum=Curriculum(start=args.stage), max_episode_steps=200
    )
    obs_dim = env.observation_size
    agent = build(a, obs_dim)
    agent.schedule(0, args.stage)
    buf = Replay(ReplayConfig(), 100_000, obs_dim, env.num_envs * env.n_agents, a.gamma)

    n, t0 = 0, time.perf_counter()
    obs, mask = env.observe()
    while time.perf_counter() - t0 < args.seconds:
        st, k = collect(env, agent, buf, obs, mask)
        obs, mask = st.obs, st.action_mask
        n += k
    env_sps = n / (time.perf_counter() - t0)

    rng = np.random.default_rng(0)
    u, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < args.seconds:
        b = {k: torch.from_numpy(v) for k, v in buf.sample(a.batch_size, rng, 0.4).items()}
        agent.update(b)
        u += 1
    ups = u / (time.perf_counter() - t0)
    combined = 1.0 / (1.0 / env_sps + 1.0 / (a.update_every * ups))
    print(
        f"# {platform.processor() or platform.machine()}, torch {torch.__version__}, "
        f"threads {args.threads}, n_envs {args.n_envs}, stage {args.stage}, "
        f"T {a.T}, width {a.width}"
    )
    print(
        "| env steps/s (acting only) | updates/s (batch 128) "
        "| training steps/s (1 update / 4 steps) |"
    )
    print("|---:|---:|---:|")
    print(f"| {env_sps:,.0f} | {ups:,.1f} | {combined:,.0f} |")


if __name__ == "__main__":
    main()
