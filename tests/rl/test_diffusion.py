import math

import torch

from cdr_bench.rl.diffusion import Schedule, masked_softmax


def test_linear_schedule_alpha_bar_matches_paper_literal():
    s = Schedule("linear", 10)
    betas = [1e-4 + i * (2e-2 - 1e-4) / 9 for i in range(10)]
    expect = math.prod(1 - b for b in betas)
    assert abs(float(s.alpha_bar[10]) - expect) < 1e-6
    assert 0.89 < expect < 0.91  # y_T is still mostly signal
    assert float(s.alpha_bar[0]) == 1.0


def test_cosine_schedule_reaches_noise():
    s = Schedule("cosine", 10)
    assert float(s.alpha_bar[10]) < 1e-2
    assert torch.all(s.alpha_bar[1:] < s.alpha_bar[:-1])


def test_reverse_mean_eq32_by_hand():
    s = Schedule("linear", 10)
    t = 5
    betas = [1e-4 + i * (2e-2 - 1e-4) / 9 for i in range(10)]
    abar_t = math.prod(1 - b for b in betas[:t])
    abar_tm1 = math.prod(1 - b for b in betas[: t - 1])
    b = betas[t - 1]
    y0, yt = torch.randn(4, 27), torch.randn(4, 27)
    c0 = math.sqrt(abar_tm1) * b / (1 - abar_t)
    ct = math.sqrt(1 - b) * (1 - abar_tm1) / (1 - abar_t)
    assert torch.allclose(s.posterior_mean(y0, yt, t), c0 * y0 + ct * yt, atol=1e-5)
    # Eq. 29
    assert abs(float(s.beta_tilde[t]) - (1 - abar_tm1) / (1 - abar_t) * b) < 1e-7
    # t = 1: the mean is the prediction itself
    assert torch.allclose(s.posterior_mean(y0, yt, 1), y0, atol=1e-6)


def test_q_sample_marginal():
    s = Schedule("cosine", 10)
    y0 = torch.full((20000, 27), 2.0)
    t = torch.full((20000,), 4)
    yt = s.q_sample(y0, t, torch.randn_like(y0))
    a = float(s.alpha_bar[4])
    assert abs(yt.mean().item() - 2 * math.sqrt(a)) < 0.01
    assert abs(yt.var().item() - (1 - a)) < 0.01


def test_masked_softmax_puts_no_mass_on_masked_classes():
    g = torch.Generator().manual_seed(0)
    logits = torch.randn(64, 27, generator=g) * 10
    mask = (torch.rand(64, 27, generator=g) > 0.5).to(torch.int8)
    mask[:, 13] = 1
    p = masked_softmax(logits, mask)
    assert torch.all(p[mask == 0] == 0)
    assert torch.allclose(p.sum(-1), torch.ones(64))


def test_trainer_schedule_names_match_the_diffusion_module():
    from cdr_bench.rl import diffusion, train_diffusion_ac

    assert train_diffusion_ac.SCHEDULES == diffusion.SCHEDULES
