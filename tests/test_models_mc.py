"""The one copy of MC dropout and of its summaries (crossing_assist.models.mc), against a plain
numpy reference, and the places that share it: the policy heads, the bundle graph and the IIL
learners."""

import numpy as np
import pytest
import torch

from crossing_assist.models.mc import mc_dropout, mc_summaries


def reference_summaries(logits: np.ndarray, temperature: float = 1.0):
    """numpy float64 reference: per-sample softmax p_t [T, N, A]; probs = mean_t p_t;
    entropy = H(probs); mutual_info = max(0, H(probs) - mean_t H(p_t)); variance and votes."""
    z = logits / temperature
    p = np.exp(z - z.max(-1, keepdims=True))
    p /= p.sum(-1, keepdims=True)

    def h(q):
        return -np.sum(np.where(q > 0, q * np.log(np.where(q > 0, q, 1.0)), 0.0), -1)

    probs = p.mean(0)
    ent = h(probs)
    mi = np.maximum(ent - h(p).mean(0), 0.0)
    var = ((p - probs) ** 2).mean(0)
    votes = np.stack([(p.argmax(-1) == a).mean(0) for a in range(p.shape[-1])], -1)
    return probs, ent, mi, var, votes


@pytest.mark.parametrize("dtype, tol", [(torch.float32, 2e-6), (torch.float64, 1e-12)])
@pytest.mark.parametrize("temperature", [1.0, 1.7])
def test_summaries_match_the_numpy_reference(dtype, tol, temperature):
    rng = np.random.default_rng(3)
    logits = rng.normal(0.0, 3.0, size=(16, 5, 13))
    logits[:, 0] = 0.0  # every sample the same: mutual information exactly 0
    logits[:4, 1, 2] = 80.0  # near one-hot samples: 0 log 0 must count as 0
    got = mc_summaries(torch.as_tensor(logits, dtype=dtype), temperature)
    want = reference_summaries(logits, temperature)
    for g, w, name in zip(got, want, ("probs", "entropy", "mutual_info", "variance", "votes")):
        assert g.dtype == dtype, name
        np.testing.assert_allclose(g.numpy(), w, rtol=0, atol=tol, err_msg=name)
    assert float(got[2][0]) == 0.0 and np.all(got[2].numpy() >= 0)


def test_dropout_with_a_generator_is_reproducible_and_unbiased():
    x = torch.ones(4, 50_000)
    a = mc_dropout(x, 0.5, True, torch.Generator().manual_seed(7))
    b = mc_dropout(x, 0.5, True, torch.Generator().manual_seed(7))
    assert torch.equal(a, b) and set(torch.unique(a).tolist()) == {0.0, 2.0}
    assert abs(float(a.mean()) - 1.0) < 0.02  # sd 0.0022: a 9-sigma margin
    y = mc_dropout(torch.ones(100_000), 0.2, True, torch.Generator().manual_seed(1))
    assert set(torch.unique(y).tolist()) == {0.0, 1.25}
    assert torch.equal(mc_dropout(x, 0.5, False), x) and torch.equal(mc_dropout(x, 0.0, True), x)


def test_heads_graph_and_iil_use_the_one_copy():
    from crossing_assist.export import graph
    from crossing_assist.iil import learners, networks
    from crossing_assist.models import heads

    assert heads.mc_dropout is networks.mc_dropout is mc_dropout
    assert graph.mc_summaries is learners.mc_summaries is mc_summaries


def test_iil_uncertainty_is_the_graph_entropy_or_mutual_info():
    import gymnasium as gym

    from crossing_assist.iil.learners import ActionCodec

    codec = ActionCodec(gym.spaces.Discrete(4))
    out = torch.tensor([[[2.0, 0.0, 0.0, -1.0]], [[0.0, 2.5, 0.0, 0.0]], [[1.0, 0.5, 0.0, 0.0]]])  # T x 1 x A
    probs, ent, mi, _, _ = reference_summaries(out.double().numpy())
    a, u = codec.decode(out)
    assert a == int(probs[0].argmax()) and u == pytest.approx(ent[0], abs=1e-12)
    a, u = codec.decode(out, measure="mutual_info")
    assert u == pytest.approx(mi[0], abs=1e-12) and u > 0
