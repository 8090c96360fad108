"""Reinforcement-learning building blocks (torch lives here and in agents/, nowhere else).

Modules: :mod:`diffusion` (DDPM schedule and kernels in logit space, Eq. 27-33),
:mod:`networks` (denoiser, twin critics, categorical actor), :mod:`replay` (uniform replay),
:mod:`vecenv` (batched training environment with auto-reset and the DPSC curriculum),
:mod:`diffusion_ac` (Algorithm 1 and the policy), :mod:`train_diffusion_ac` (Algorithm 2),
:mod:`cli` (``train``, ``multimodal``, ``latency`` subcommands).
"""
