"""The shipped learned agents compute the same action bits on any x86-64 CPU.

Two subprocesses stand in for two CPUs: one with the default kernel choices, one with every
CPU-dispatched library forced down to its baseline kernels (torch's ATen capability, numpy's
SIMD dispatch, OpenBLAS's and MKL's core type, oneDNN's ISA, glibc's libm variants and numba's
LLVM target). Each loads every leaderboard entry whose agent is a shipped learned agent (the
Diffusion-AC ablation checkpoints included), decides for a fixed set of real observations (a
rollout of ``high``) in batches of many sizes, and reports the actions and the raw network
outputs. They must be byte-identical. Each child also prints fingerprints proving its kernel
settings took effect; the host-CPU child compiles the kernels afresh and checks the generated
machine code for fused multiply-adds and libm calls (tests/kernel_code.py; in CI the warm-up
does, which compiles them afresh anyway); and both report what the PyTorch modules (the former
inference path) compute on the same inputs -- which, under these settings, is not the same.

Run by hand (``python tests/leaderboard/test_cpu_independence.py``) to print the comparison.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from cdr_bench.evaluate.sandbox import CPU_KNOBS
from tests.kernel_code import INSPECTED_ENV

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = ("diffusion_ac", "ppo", "maskable_ppo", "td3", "rainbow", "safe_dqn_x")
"""The learned agents whose inference must not depend on the CPU (agents/<name>)."""
RESET_SEED = 20261123
KNOBS = CPU_KNOBS
"""Every kernel setting the scorer passes on to an agent (cdr_bench.evaluate.sandbox)."""


def _numpy_cpu() -> Any:
    try:
        from numpy._core import _multiarray_umath as m  # numpy 2
    except ImportError:  # pragma: no cover - numpy 1
        from numpy.core import _multiarray_umath as m
    return m


def baseline_kernel_env() -> dict[str, str]:
    """Settings that make this CPU compute like an older one (SSE-only kernels)."""
    m = _numpy_cpu()
    # numpy refuses (with a warning) to disable a feature that is not a dispatch target
    dispatched = [f for f in m.__cpu_dispatch__ if m.__cpu_features__.get(f)]
    return {
        "ATEN_CPU_CAPABILITY": "default",
        "NPY_DISABLE_CPU_FEATURES": " ".join(dispatched),
        "OPENBLAS_CORETYPE": "Prescott",
        "MKL_ENABLE_INSTRUCTIONS": "SSE4_2",
        "ONEDNN_MAX_CPU_ISA": "SSE41",
        "NUMBA_CPU_NAME": "generic",
        "GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX512F,-AVX2,-FMA,-FMA4",
    }


def learned_entries() -> list[dict[str, Any]]:
    """Leaderboard submissions whose agent is a shipped learned agent."""
    out = []
    for p in sorted((ROOT / "leaderboard" / "submissions").glob("*.yaml")):
        sub = yaml.safe_load(p.read_text())
        agent = str(sub["agent"]).rstrip("/")
        name = agent.removeprefix("agents/").removesuffix("/agent.py")
        if name in SHIPPED:
            ck = sub.get("checkpoint") or f"agents/{name}/checkpoint.pt"
            out.append({"entry": p.stem, "agent": name, "checkpoint": ck})
    return out


def simulator_states(n_episodes: int = 48, steps: int = 8) -> dict[str, np.ndarray]:
    """Observations and masks of every flying aircraft along random feasible actions in
    ``high`` (a few hundred real states), cut into batches of many sizes."""
    from cdr_bench.scenarios import load_scenario
    from cdr_bench.sim import Simulator, observe

    sim = Simulator(load_scenario("high"), n_episodes=n_episodes)
    sim.reset(np.arange(n_episodes))
    rng = np.random.default_rng(7)
    obs, masks = [], []
    for _ in range(steps):
        active = sim.ac_active.copy()
        if not active.any():
            break
        m = sim.action_masks()
        obs.append(observe(sim)[active])
        masks.append(m[active])
        sim.step(np.argmax(rng.random(m.shape) * (m != 0), axis=-1))
    o = np.concatenate(obs).astype(np.float32)
    sizes, left, s = [], len(o), 1
    for s in (1, 2, 3, 5, 8, 13, 21, 34, 55, 89, 144):
        if left <= 0:
            break
        sizes.append(min(s, left))
        left -= sizes[-1]
    while left > 0:
        sizes.append(min(s, left))
        left -= sizes[-1]
    return {
        "obs": o,
        "masks": np.concatenate(masks).astype(np.int8),
        "sizes": np.asarray(sizes, np.int64),
    }


# ----------------------------------------------------------------------------------------------
# The child process


def _sha(*arrays: Any) -> str:
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(str((a.dtype.str, a.shape)).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:16]


def _fingerprints() -> dict[str, Any]:
    """Which kernels this process picked, and a digest of what each library computes."""
    import ctypes
    import glob
    import math

    import numba
    import torch

    features = _numpy_cpu().__cpu_features__

    rng = np.random.default_rng(0)
    a = rng.normal(size=(64, 128)).astype(np.float32)
    b = rng.normal(size=(128, 96)).astype(np.float32)
    x = rng.uniform(-5, 5, 20000)
    fp: dict[str, Any] = {
        "torch_capability": torch.backends.cpu.get_cpu_capability(),
        "numpy_x86_v3": bool(features.get("X86_V3", features.get("AVX2"))),
        "numba_cpu": numba.config.CPU_NAME or "host",
        "torch_matmul": _sha((torch.as_tensor(a) @ torch.as_tensor(b)).numpy()),
        "torch_tanh_exp": _sha(
            torch.tanh(torch.as_tensor(a)).numpy(), torch.exp(torch.as_tensor(a)).numpy()
        ),
        "torch_randn": _sha(torch.randn(4096, generator=torch.Generator().manual_seed(0)).numpy()),
        "numpy_matmul": _sha(a @ b),
        "numpy_tanh_exp": _sha(np.tanh(a), np.exp(a), np.exp(x)),
        "libm_exp_log_tanh": _sha(
            np.array([(math.exp(v), math.log1p(abs(v)), math.tanh(v)) for v in x])
        ),
    }
    libs = glob.glob(
        os.path.join(os.path.dirname(np.__file__), os.pardir, "numpy.libs", "*openblas*")
    )
    for lib in libs:
        try:
            f = ctypes.CDLL(lib).scipy_openblas_get_corename64_
            f.restype = ctypes.c_char_p
            fp["openblas_core"] = f().decode()
        except (OSError, AttributeError):
            pass
    return fp


def _load_agent(agent: str, checkpoint: str) -> Any:
    path = ROOT / "agents" / agent / "agent.py"
    spec = importlib.util.spec_from_file_location(f"_cpu_indep_{agent}", path)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.Agent(None, None, checkpoint=str(ROOT / checkpoint))


def _raw_outputs(agent: Any, obs: np.ndarray) -> list[np.ndarray]:
    """The networks' outputs before the decision (noise fixed for the diffusion actor)."""
    if hasattr(agent, "actor"):  # Diffusion-AC
        actor = agent.actor
        if actor.kind == "categorical":
            return [actor.clean_logits(obs)]
        noise = np.random.default_rng(3).standard_normal((actor.T, len(obs), 27), np.float32)
        return [actor.clean_logits(obs, noise)]
    net = agent.net
    if hasattr(net, "q_values"):  # Rainbow
        return [net.q_values(obs)]
    if hasattr(net, "safety"):  # Safe-DQN-X
        return [net.safety(obs), net.goal(obs)]
    return [net(obs)]  # PPO, MaskablePPO, TD3


def _torch_reference(agent: str, checkpoint: str, data: dict[str, np.ndarray]) -> dict[str, str]:
    """What the PyTorch modules (the former inference path) compute on the same inputs."""
    import torch

    path = str(ROOT / checkpoint)
    obs_t = torch.as_tensor(data["obs"])
    mask_t = torch.as_tensor(data["masks"])
    with torch.no_grad():
        if agent == "diffusion_ac":
            from cdr_bench.rl.diffusion_ac import load_policy

            pol = load_policy(path)
            gen = torch.Generator().manual_seed(RESET_SEED)
            acts, start = [], 0
            for n in data["sizes"]:
                acts.append(pol.act(obs_t[start : start + n], mask_t[start : start + n], gen))
                start += int(n)
            raw = pol.net.enc(obs_t)  # the state encoder (the rest depends on the noise)
            return {"actions": _sha(torch.cat(acts).numpy()), "raw": _sha(raw.numpy())}
        if agent == "rainbow":
            from cdr_bench.rl.rainbow import load_net

            net = load_net(path)
            q = net.q_values(obs_t)
            return {"actions": _sha(net.act(obs_t, mask_t).numpy()), "raw": _sha(q.numpy())}
        if agent == "safe_dqn_x":
            from cdr_bench.rl.safe_dqn import load_net as load_safe

            net = load_safe(path)
            qs, qg = net(obs_t)
            return {
                "actions": _sha(net.act(obs_t, mask_t).numpy()),
                "raw": _sha(qs.numpy(), qg.numpy()),
            }
        from cdr_bench.rl.sb3_policies import load_actor

        actor, _ = load_actor(path)
        out = actor(obs_t)
        return {"actions": _sha(out.argmax(1).numpy()), "raw": _sha(out.numpy())}


def _fma_in_kernels() -> dict[str, list[str]]:
    """Fused multiply-adds and libm calls in every compiled kernel of cdr_bench.inference
    (tests/kernel_code.py; this process must have compiled them, not loaded them from the
    cache)."""
    import cdr_bench.inference as inf
    from tests.kernel_code import inspect_module

    return inspect_module(inf)


def child(spec_path: str, out_path: str) -> None:
    spec = json.loads(Path(spec_path).read_text())
    data = dict(np.load(spec["states"]))
    result: dict[str, Any] = {"fingerprints": _fingerprints(), "entries": {}}
    t0 = time.perf_counter()
    for e in spec["entries"]:
        agent = _load_agent(e["agent"], e["checkpoint"])
        agent.reset(RESET_SEED)
        acts, start = [], 0
        for n in data["sizes"]:
            a = agent.act_batch(data["obs"][start : start + n], data["masks"][start : start + n])
            acts.append(np.asarray(a, np.int64))
            start += int(n)
        actions = np.concatenate(acts)
        result["entries"][e["entry"]] = {
            "actions": actions.tolist(),
            "raw": _sha(*_raw_outputs(agent, data["obs"])),
            "torch": _torch_reference(e["agent"], e["checkpoint"], data),
        }
    result["seconds"] = time.perf_counter() - t0
    if spec.get("check_fma"):
        result["fma"] = _fma_in_kernels()
    Path(out_path).write_text(json.dumps(result))


# ----------------------------------------------------------------------------------------------
# The test


def run_both(tmp: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """(default child, baseline-kernels child) results."""
    tmp.mkdir(parents=True, exist_ok=True)
    np.savez(tmp / "states.npz", **simulator_states())
    base = {k: v for k, v in os.environ.items() if k not in KNOBS}
    base["PYTHONPATH"] = os.pathsep.join([str(ROOT), base.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    base["OMP_NUM_THREADS"] = "1"
    procs = []
    # CI inspects the code of every kernel it compiles (.ci/warm_kernels.py); otherwise the
    # default child does it here
    inspect = not os.environ.get(INSPECTED_ENV)
    for label, extra in (("default", {}), ("baseline", baseline_kernel_env())):
        spec = {
            "states": str(tmp / "states.npz"),
            "entries": learned_entries(),
            "check_fma": label == "default" and inspect,
        }
        (tmp / f"{label}.json").write_text(json.dumps(spec))
        # The default child compiles its kernels afresh (a cache of its own) when it inspects
        # their machine code; the baseline child loads numba's generic-CPU entries from the
        # package's cache, or compiles them there (numba keeps each CPU target's entries apart,
        # so it never loads the host CPU's code).
        env = {**base, **extra}
        if spec["check_fma"]:
            env["NUMBA_CACHE_DIR"] = str(tmp / "numba-default")
        argv = [
            sys.executable,
            __file__,
            "--child",
            str(tmp / f"{label}.json"),
            str(tmp / f"{label}.out.json"),
        ]
        log = open(tmp / f"{label}.log", "w")  # closed once the child exits
        procs.append(
            (label, subprocess.Popen(argv, cwd=ROOT, env=env, stdout=log, stderr=log), log)
        )
    results = []
    for label, proc, log in procs:
        code = proc.wait(timeout=900)
        log.close()
        if code != 0:
            raise AssertionError(
                f"{label} child failed:\n" + (tmp / f"{label}.log").read_text()[-4000:]
            )
        results.append(json.loads((tmp / f"{label}.out.json").read_text()))
    return results[0], results[1]


def compare(a: dict[str, Any], b: dict[str, Any]) -> tuple[list[str], list[str]]:
    """(differences of the fixed path, entries whose PyTorch reference differs)."""
    bad, torch_differs = [], []
    for name, ea in a["entries"].items():
        eb = b["entries"][name]
        if ea["actions"] != eb["actions"]:
            i = next(
                i
                for i, (x, y) in enumerate(zip(ea["actions"], eb["actions"], strict=True))
                if x != y
            )
            n = sum(x != y for x, y in zip(ea["actions"], eb["actions"], strict=True))
            bad.append(f"{name}: {n} of {len(ea['actions'])} actions differ (first at state {i})")
        if ea["raw"] != eb["raw"]:
            bad.append(f"{name}: network outputs differ ({ea['raw']} vs {eb['raw']})")
        ta, tb = ea["torch"], eb["torch"]
        what = [k for k in ("actions", "raw") if ta[k] != tb[k]]
        if what:
            torch_differs.append(f"{name} ({' and '.join(what)})")
    return bad, torch_differs


@pytest.mark.slow
@pytest.mark.skipif(
    platform.machine().lower() not in ("x86_64", "amd64"), reason="the settings are x86-64's"
)
def test_learned_agents_identical_under_two_kernel_settings(tmp_path):
    pytest.importorskip("torch")  # the agents read their checkpoints with torch.load
    entries = learned_entries()
    assert {e["agent"] for e in entries} == set(SHIPPED), "a shipped learned agent has no entry"
    default, baseline = run_both(tmp_path)
    fb = baseline["fingerprints"]
    assert fb["torch_capability"] == "DEFAULT" and fb["numba_cpu"] == "generic", fb
    assert not fb["numpy_x86_v3"], fb
    if "fma" in default:  # else inspected by CI's warm-up (INSPECTED_ENV)
        fma = {k: v for k, v in default["fma"].items() if v}
        assert default["fma"] and not fma, f"in the generated code: {fma}"
    bad, torch_differs = compare(default, baseline)
    changed = [k for k in default["fingerprints"] if default["fingerprints"][k] != fb[k]]
    print(f"kernel fingerprints that changed: {changed}")
    print(f"PyTorch reference differs for: {torch_differs or 'none'}")
    assert not bad, "the fixed numeric path depends on the kernel settings:\n" + "\n".join(bad)
    n = len(next(iter(default["entries"].values()))["actions"])
    assert n >= 200, f"only {n} states"


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] == "--child":
        child(sys.argv[2], sys.argv[3])
    else:
        import tempfile

        with tempfile.TemporaryDirectory() as d:
            t = time.perf_counter()
            da, db = run_both(Path(d))
            bad, torch_differs = compare(da, db)
            for k in da["fingerprints"]:
                print(
                    f"{k:20} default {da['fingerprints'][k]!s:18} baseline {db['fingerprints'][k]}"
                )
            print(f"problems in {len(da['fma'])} kernels: {sum(map(len, da['fma'].values()))}")
            print(f"fixed path differences: {bad or 'none'}")
            print(f"PyTorch reference differs for: {torch_differs or 'none'}")
            n_states = len(next(iter(da["entries"].values()))["actions"])
            print(f"states: {n_states}, {time.perf_counter() - t:.1f} s")
