"""Reinforcement-learning building blocks (torch lives here and in agents/, nowhere else).

Learners: :mod:`diffusion` (DDPM schedule and kernels in logit space, Eq. 27-33),
:mod:`networks` (denoiser, twin critics, categorical actor), :mod:`diffusion_ac` (Algorithm 1
and the policy), :mod:`rainbow`, :mod:`safe_dqn`, :mod:`sb3_policies` (the SB3 actors as plain
weight files). Training: :mod:`curriculum` (the training environment on the batched VectorEnv,
with the DPSC curriculum), :mod:`replay`, :mod:`offpolicy` (the loop of Diffusion-AC, Rainbow-DQN
and Safe-DQN-X, whose flags and learners are in :mod:`train_diffusion_ac`, :mod:`train_rainbow`
and :mod:`train_safe_dqn`), :mod:`train_sb3` (PPO, MaskablePPO and TD3), :mod:`common` (what
every trainer shares), :mod:`quick_eval`, :mod:`cli` (``cdr-bench train``).
"""
