"""The numpy network core: activations, layers, Adam, training loops."""

import numpy as np
import pytest

from fricli.core.errors import FitError
from fricli.numerics.nn import activations as acts
from fricli.numerics.nn.adam import Adam
from fricli.numerics.nn import network as network_module
from fricli.numerics.nn.heads import DissipativeHead, HeadedNetwork
from fricli.numerics.nn.network import Groups, Network
from fricli.numerics.nn.training import CHUNK_MIN, Standardizer, Trainer, _sse_and_grad, sse


def finite_difference(f, x, eps=1e-6):
    return (f(x + eps) - f(x - eps)) / (2 * eps)


# ---------------------------------------------------------------------------- activations

PAIRS = [
    ("elu", acts.elu, acts.elu_grad),
    ("sigmoid", acts.sigmoid, acts.sigmoid_grad),
    ("identity", acts.identity, acts.identity_grad),
] + [(f"jump{k}", lambda x, k=k: acts.jump(x, k), lambda x, k=k: acts.jump_grad(x, k)) for k in range(1, 11)]


@pytest.mark.parametrize("name,f,grad", PAIRS, ids=[p[0] for p in PAIRS])
def test_activation_gradient_matches_finite_differences(name, f, grad):
    x = np.concatenate([np.linspace(-6, -0.01, 40), np.linspace(0.01, 6, 40)])  # away from the kink at 0
    np.testing.assert_allclose(grad(x), finite_difference(f, x), rtol=1e-5, atol=1e-7)


def test_elu_values_and_no_overflow():
    x = np.array([-1e4, -50.0, -1.0, 0.0, 2.0, 1e4, 3e38], dtype=np.float32)
    with np.errstate(over="raise", invalid="raise", divide="raise"):
        y, d = acts.elu(x), acts.elu_grad(x)
    np.testing.assert_allclose(y[:5], [-1.0, np.expm1(-50.0), np.expm1(-1.0), 0.0, 2.0], rtol=1e-6)
    assert y[-1] == np.float32(3e38) and (d[4:] == 1).all()
    h = x[None, :].copy()
    a, dd = np.empty_like(h), np.empty_like(h)
    with np.errstate(over="raise", invalid="raise", divide="raise"):
        acts.ELU().forward(h, a, dd)
    np.testing.assert_array_equal(a[0], y)
    np.testing.assert_array_equal(dd[0], d)


def test_sigmoid_saturates_without_warnings():
    x = np.array([-1e4, 0.0, 1e4], dtype=np.float32)
    with np.errstate(over="raise", invalid="raise", divide="raise"):
        y = acts.sigmoid(x)
    np.testing.assert_allclose(y, [0.0, 0.5, 1.0], atol=1e-12)


def test_jump_is_zero_left_of_zero_and_one_far_right():
    x = np.array([-3.0, -1e-9, 0.0, 50.0])
    for k in (1, 4, 10):
        np.testing.assert_allclose(acts.jump(x, k), [0, 0, 0, 1], atol=1e-12)
        assert acts.jump_grad(x, k)[0] == 0
    assert acts.jump_grad(np.array([0.0]), 1)[0] == 1.0  # right derivative at 0 for k = 1


@pytest.mark.parametrize("spec", ["elu", "sigmoid", "identity", {"name": "jump", "k": [1, 2, 3, 7]},
                                  {"name": "mixed", "parts": [[2, "sigmoid"], [2, {"name": "jump", "k": [1, 5]}]]}])
def test_fused_forms_match_plain_pairs(spec, rng):
    act = acts.from_spec(spec)
    h = rng.normal(0, 2, (4, 50)).astype(np.float32)
    a, d = np.empty_like(h), np.empty_like(h)
    act.forward(h, a, d)
    x = h.astype(np.float64)
    name = spec if isinstance(spec, str) else spec["name"]
    if name == "jump":
        k = np.array(spec["k"])[:, None]
        want, want_d = acts.jump(x, k), acts.jump_grad(x, k)
    elif name == "mixed":
        want = np.vstack([acts.sigmoid(x[:2]), acts.jump(x[2:], np.array([[1], [5]]))])
        want_d = np.vstack([acts.sigmoid_grad(x[:2]), acts.jump_grad(x[2:], np.array([[1], [5]]))])
    else:
        want, want_d = getattr(acts, name)(x), getattr(acts, f"{name}_grad")(x)
    np.testing.assert_allclose(a, want, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(d, want_d, rtol=1e-5, atol=1e-6)
    assert acts.from_spec(act.spec()).spec() == act.spec()
    for dtype in (np.float32, np.float64):        # the values alone, as prediction computes them
        hv = h.astype(dtype)
        with_d, alone, scratch = np.empty_like(hv), np.empty_like(hv), np.empty_like(hv)
        act.forward(hv, with_d, np.empty_like(hv))
        act.value(hv, alone, scratch)
        np.testing.assert_allclose(alone, with_d, rtol=2 * np.finfo(dtype).eps, atol=2 * np.finfo(dtype).eps)


def test_unknown_activation_refused():
    with pytest.raises(ValueError):
        acts.from_spec("relu6")
    with pytest.raises(ValueError):
        acts.Jump([0, 1])


# ---------------------------------------------------------------------------- network


def networks():
    yield "elu-2x", Network(2, [(5, acts.ELU()), (4, acts.ELU())], dtype=np.float64)
    yield "selmic", Network(2, [(6, acts.Mixed([(3, acts.Sigmoid()), (3, acts.Jump([1, 2, 3]))]))], dtype=np.float64)
    yield "skip", Network(2, [(5, acts.Sigmoid())], n_skip=2, dtype=np.float64)
    yield "two-outputs", Network(3, [(4, acts.ELU())], n_out=2, dtype=np.float64)
    yield "linear", Network(2, [], dtype=np.float64)


@pytest.mark.parametrize("name,net", list(networks()), ids=[n for n, _ in networks()])
def test_network_gradient_matches_finite_differences(name, net, rng):
    net.init(rng)
    n = 17
    x = rng.normal(size=(net.n_in + net.n_skip, n))
    if net.n_skip:
        x[net.n_in:] = rng.integers(0, 2, size=(net.n_skip, n))
    t = rng.normal(size=(net.n_out, n))
    ws = net.workspace(n)
    ws.set_inputs(x)
    grad = np.empty_like(net.theta)
    scale = 2.0 / (n * net.n_out)
    _sse_and_grad(net, ws, t, grad, scale)

    def loss(theta):
        saved = net.theta.copy()
        net.theta[:] = theta
        value = sse(net, x, t) / (n * net.n_out)
        net.theta[:] = saved
        return value

    eps = 1e-6
    numeric = np.empty_like(grad)
    for i in range(net.n_params):
        e = np.zeros_like(net.theta)
        e[i] = eps
        numeric[i] = (loss(net.theta + e) - loss(net.theta - e)) / (2 * eps)
    np.testing.assert_allclose(grad, numeric, rtol=1e-4, atol=1e-8)


def repeated_inputs(net, rng, distinct=7, n=60):
    """Inputs (rows as set_inputs, n) whose layer rows take ``distinct`` values in shuffled order;
    the rows after them (a head's aux rows) differ from sample to sample."""
    base = rng.normal(size=(net.layer_rows, distinct))
    if net.n_skip:
        base[net.n_in:] = rng.integers(0, 2, size=(net.n_skip, distinct))
    x = base[:, rng.integers(0, distinct, size=n)]
    aux = rng.uniform(0.1, 2.0, size=(getattr(getattr(net, "head", None), "n_aux", 0), n))
    return np.vstack([x, aux])


def grouped_networks():
    yield from networks()
    yield "dissipative", HeadedNetwork(2, [(6, acts.ELU()), (5, acts.ELU())], DissipativeHead(), dtype=np.float64,
                                       constant_outputs=(1,))


@pytest.mark.parametrize("name,net", list(grouped_networks()), ids=[n for n, _ in grouped_networks()])
def test_repeated_inputs_are_computed_once_with_the_same_loss_and_gradient(name, net, rng):
    net.init(rng)
    x = repeated_inputs(net, rng)
    n = x.shape[1]
    t = rng.normal(size=(1 if isinstance(net, HeadedNetwork) else net.n_out, n))
    plain = net.workspace(n)
    plain.set_inputs(x)
    grouped = net.workspace_for(x)
    assert plain.groups is None and grouped.groups.m == 7 and grouped.a[0].shape[1] == 7
    results = []
    for ws in (plain, grouped):
        grad = np.empty_like(net.theta)
        loss = _sse_and_grad(net, ws, t, grad, 2.0 / n)
        results.append((loss, grad))
    assert results[1][0] == pytest.approx(results[0][0], rel=1e-12)
    np.testing.assert_allclose(results[1][1], results[0][1], rtol=1e-10, atol=1e-13)


def test_wide_batches_run_in_column_pieces_with_the_same_outputs_and_gradient(rng):
    """The default dissipative network on 2,500 columns: the layers' products run over pieces of
    columns (faster small-matrix kernels); the outputs are those of one product over all columns
    to float32 rounding (the same bits where the BLAS's two kernels order each column's dot
    product alike, as OpenBLAS's Skylake-X kernels do and its Haswell kernels do not), the
    gradient the same sums added in pieces."""
    net = HeadedNetwork(2, [(30, acts.ELU()), (30, acts.ELU())], DissipativeHead(), constant_outputs=(1,))
    net.init(rng)
    n = 2500
    x = np.vstack([rng.normal(size=(2, n)), np.tanh(rng.normal(size=(1, n))), rng.uniform(0, 2, size=(1, n))])
    t = rng.normal(size=(1, n)).astype(np.float32)
    whole, pieces = net.workspace(n), net.workspace(n)
    whole.pieces = None
    assert [(p.start, p.stop) for p in pieces.pieces] == [(0, 1024), (1024, 2048), (2048, 2500)]
    grads = []
    for ws in (whole, pieces):
        ws.set_inputs(x)
        grad = np.empty_like(net.theta)
        _sse_and_grad(net, ws, t, grad, 2.0 / n)
        grads.append(grad)
    for a, b in zip(whole.a + whole.h + whole.g, pieces.a + pieces.h + pieces.g):
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-5 * np.abs(a).max())
    np.testing.assert_allclose(grads[1], grads[0], rtol=2e-5, atol=1e-6 * np.abs(grads[0]).max())
    assert not np.array_equal(grads[1], grads[0])      # the pieces did run: another order of the sums
    assert network_module.column_pieces(Network(2, [(64, acts.ELU())] * 2), n) is None   # too wide a layer
    assert network_module.column_pieces(net, 1024) is None


@pytest.mark.parametrize("name", ["dissipative", "skip"])
def test_prediction_runs_piece_by_piece_with_the_same_bits(name, rng):
    """Without backward, forward runs every layer on one piece of columns at a time: the outputs of
    every layer over all columns at once, and of one product over all columns, to float32 rounding
    (bit for bit where the BLAS computes each column alike whatever the product's width, as
    OpenBLAS's Skylake-X kernels do and its Haswell kernels do not); predict takes that path."""
    if name == "dissipative":
        net = HeadedNetwork(2, [(30, acts.ELU()), (30, acts.ELU())], DissipativeHead(), constant_outputs=(1,))
        extra = np.vstack([np.tanh(rng.normal(size=(1, 2500))), rng.uniform(0, 2, size=(1, 2500))])
    else:
        net = Network(3, [(30, acts.ELU()), (30, acts.Sigmoid())], n_skip=2)
        extra = rng.integers(0, 2, size=(2, 2500)).astype(float)
    net.init(rng)
    x = np.vstack([rng.normal(size=(net.n_in, 2500)), extra])
    pieces, layers, whole = (net.workspace(2500, backward=False) for _ in range(3))
    assert sorted(pieces.part) == [452, 1024] and net.workspace(2500).part is None
    layers.part = None
    whole.part = whole.pieces = None
    for ws in (pieces, layers, whole):
        ws.set_inputs(x)
    by_piece = net.forward(pieces).copy()
    assert np.array_equal(net.predict(x, chunk=2500), by_piece)
    for ws in (layers, whole):
        other = net.forward(ws)
        np.testing.assert_allclose(by_piece, other, rtol=0, atol=1e-5 * np.abs(other).max())


def test_groups_are_bit_for_bit(rng):
    key = np.array([[0.0, -0.0, 1.0, np.nan, 0.0, 1.0, np.nan],
                    [2.0, 2.0, 3.0, 4.0, 2.0, 3.0, 4.0]], dtype=np.float32)
    g = Groups.of(key)
    assert g.m == 4            # -0.0 is not 0.0 to the bits; the NaN columns are one bit pattern
    rebuilt = key[:, g.first][:, g.index]
    assert rebuilt.tobytes() == key.tobytes()
    assert (g.index[g.order] == np.sort(g.index)).all() and (g.index[g.order][g.starts] == np.arange(g.m)).all()


def test_distinct_inputs_get_a_plain_workspace(rng):
    net = Network(2, [(5, acts.ELU())]).init(rng)
    x = rng.normal(size=(2, 50))
    assert net.workspace_for(x).groups is None
    x[:, 26:] = x[:, :24]          # 26 distinct columns of 50: more than half, not worth grouping
    assert net.workspace_for(x).groups is None
    x[:, 25] = x[:, 0]             # 25 of 50
    assert net.workspace_for(x).groups.m == 25


def test_training_on_repeated_inputs_follows_the_plain_path(monkeypatch):
    rng = np.random.default_rng(4)
    net0 = HeadedNetwork(2, [(8, acts.ELU()), (8, acts.ELU())], DissipativeHead(), dtype=np.float64,
                         constant_outputs=(1,)).init(rng)
    x = repeated_inputs(net0, rng, distinct=20, n=400)
    t = rng.normal(size=(1, 400))
    runs = []
    for share in (network_module.REPEATS_WORTHWHILE, 0.0):          # 0: never group
        monkeypatch.setattr(network_module, "REPEATS_WORTHWHILE", share)
        net = net0.astype(np.float64)
        tr = Trainer(steps=40).fit(net, x, t, x[:, :100], t[:, :100], rng=np.random.default_rng(0))
        runs.append((net.theta.copy(), tr.history_val_))
    np.testing.assert_allclose(runs[0][0], runs[1][0], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(runs[0][1], runs[1][1], rtol=1e-9)


def test_bias_is_folded_into_the_last_column(rng):
    net = Network(2, [(3, acts.Identity())]).init(rng)
    x = rng.normal(size=(2, 5)).astype(np.float32)
    w0, w1 = net.weights
    want = w1[:, :3] @ (w0[:, :2] @ x + w0[:, 2:]) + w1[:, 3:]
    np.testing.assert_allclose(net.predict(x), want, rtol=1e-5, atol=1e-6)


def test_weights_are_views_of_theta(rng):
    net = Network(2, [(4, acts.ELU())]).init(rng)
    net.theta[:] = 0
    assert all((w == 0).all() for w in net.weights)
    assert net.n_params == 4 * 3 + 1 * 5


def test_predict_in_chunks_matches_one_pass(rng):
    net = Network(2, [(8, acts.ELU()), (8, acts.ELU())]).init(rng)
    x = rng.normal(size=(2, 1000)).astype(np.float32)
    np.testing.assert_allclose(net.predict(x, chunk=97), net.predict(x, chunk=1000), rtol=1e-6, atol=1e-6)


def test_spec_round_trip(rng):
    net = Network(2, [(6, acts.Mixed([(3, acts.Sigmoid()), (3, acts.Jump([1, 2, 3]))]))], n_skip=2).init(rng)
    copy = Network.from_spec(net.spec(), [w.copy() for w in net.weights])
    x = rng.normal(size=(4, 30)).astype(np.float32)
    np.testing.assert_array_equal(copy.predict(x), net.predict(x))
    with pytest.raises(ValueError, match="shape"):
        copy.set_weights([np.zeros((2, 2))] * 2)
    with pytest.raises(ValueError, match="non-finite"):
        copy.set_weights([np.full(s, np.nan) for s in copy.shapes])


# ---------------------------------------------------------------------------- Adam


def test_adam_matches_the_reference_update(rng):
    theta = rng.normal(size=7)
    ref = theta.copy()
    m, v = np.zeros(7), np.zeros(7)
    lr, b1, b2, eps = 0.01, 0.9, 0.999, 1e-8
    opt = Adam(7, lr=lr, beta1=b1, beta2=b2, eps=eps, dtype=np.float64)
    for t in range(1, 6):
        g = rng.normal(size=7)
        opt.step(theta, g)
        m = b1 * m + (1 - b1) * g
        v = b2 * v + (1 - b2) * g * g
        mhat, vhat = m / (1 - b1 ** t), v / (1 - b2 ** t)
        ref = ref - lr * mhat / (np.sqrt(vhat) + eps)
        np.testing.assert_allclose(theta, ref, rtol=1e-12, atol=1e-14)
    assert opt.t == 5


def test_adam_first_step_moves_every_parameter_by_lr():
    theta = np.zeros(3, dtype=np.float32)
    Adam(3, lr=0.01).step(theta, np.array([2.0, -1e-3, 5.0], dtype=np.float32))
    np.testing.assert_allclose(theta, [-0.01, 0.01, -0.01], rtol=1e-4)


def test_adam_state_round_trip(rng):
    theta = rng.normal(size=5).astype(np.float32)
    opt = Adam(5, lr=0.05)
    grads = rng.normal(size=(6, 5)).astype(np.float32)
    for g in grads[:3]:
        opt.step(theta, g)
    resumed_theta = theta.copy()
    resumed = Adam.from_state(opt.state())
    for g in grads[3:]:
        opt.step(theta, g)
        resumed.step(resumed_theta, g)
    np.testing.assert_array_equal(theta, resumed_theta)
    assert resumed.state()["t"] == 6


def test_adam_refuses_bad_hyperparameters():
    with pytest.raises(ValueError):
        Adam(3, lr=0)
    with pytest.raises(ValueError):
        Adam(3, beta1=1.0)


# ---------------------------------------------------------------------------- training


def toy(rng, n):
    x = rng.uniform(-2, 2, size=(2, n))
    t = (np.sin(2 * x[0]) + 0.5 * x[1])[None, :]
    return x.astype(np.float32), t.astype(np.float32)


def small_net(rng):
    return Network(2, [(16, acts.ELU()), (16, acts.ELU())]).init(rng)


def test_full_batch_training_fits_a_smooth_function(rng):
    x, t = toy(rng, 400)
    net = small_net(rng)
    before = sse(net, x, t) / 400
    tr = Trainer(steps=1500, lr=0.01).fit(net, x, t, rng=rng)
    after = sse(net, x, t) / 400
    assert after < 0.02 * before
    assert tr.history_train_.size == tr.steps_ // tr.eval_every_ and tr.history_val_.size == 0


def test_best_weights_by_validation_loss_are_kept(rng):
    x, t = toy(rng, 300)
    xv, tv = toy(rng, 100)
    net = small_net(rng)
    tr = Trainer(steps=600, lr=0.05, eval_every=10).fit(net, x, t, xv, tv, rng=rng)
    best = int(np.argmin(tr.history_val_))
    assert tr.best_step_ == (best + 1) * 10
    assert sse(net, xv, tv) / 100 == pytest.approx(tr.history_val_.min(), rel=1e-6)


def test_mini_batch_epochs(rng):
    x, t = toy(rng, 250)
    net = small_net(rng)
    tr = Trainer(epochs=7, batch_size=32, lr=0.01).fit(net, x, t, rng=rng)
    assert tr.steps_ == 7 * (250 // 32)
    assert tr.history_train_.size == 7            # one record per epoch
    assert sse(net, x, t) / 250 < np.var(t)


@pytest.mark.parametrize("batch_size", [0, 64])
def test_training_is_deterministic(batch_size):
    results = []
    for _ in range(2):
        rng = np.random.default_rng(7)
        x, t = toy(rng, 300)
        net = small_net(rng)
        tr = Trainer(steps=200, batch_size=batch_size).fit(net, x, t, x[:, :50], t[:, :50], rng=rng)
        results.append((net.theta.tobytes(), tr.history_train_.tobytes(), tr.history_val_.tobytes()))
    assert results[0] == results[1]


def test_two_thread_full_batch_matches_one_chunk(rng):
    n = CHUNK_MIN + 100
    x, t = toy(rng, n)
    nets = [small_net(np.random.default_rng(3)) for _ in range(3)]
    Trainer(steps=5).fit(nets[0], x, t, rng=rng)
    Trainer(steps=5).fit(nets[2], x, t, rng=rng)
    assert nets[0].theta.tobytes() == nets[2].theta.tobytes()      # the threads add up in a fixed order
    # the same steps on one chunk: gradients over two halves added
    net = nets[1]
    opt = Adam(net.n_params, lr=0.01)
    for _ in range(5):
        grad = np.zeros_like(net.theta)
        for part in (slice(0, n // 2), slice(n // 2, n)):
            ws = net.workspace(x[:, part].shape[1])
            ws.set_inputs(x[:, part])
            g = np.empty_like(net.theta)
            _sse_and_grad(net, ws, t[:, part], g, 2.0 / n)
            grad += g
        opt.step(net.theta, grad)
    np.testing.assert_allclose(nets[0].theta, nets[1].theta, rtol=1e-4, atol=1e-5)


def test_divergence_raises_fit_error(rng):
    x, t = toy(rng, 200)
    net = small_net(rng)
    with pytest.raises(FitError, match="not finite"):
        Trainer(steps=300, lr=1e30).fit(net, x, t * 1e30, rng=rng)


def test_standardizer(rng):
    x = np.vstack([rng.normal(5, 3, 1000), np.full(1000, 2.0), rng.integers(0, 2, 1000)])
    s = Standardizer(keep=(2,)).fit(x)
    z = s.transform(x)
    assert z.dtype == np.float32
    np.testing.assert_allclose(z[0].mean(), 0, atol=1e-5)
    np.testing.assert_allclose(z[0].std(), 1, atol=1e-4)
    assert s.scale_[1] == 1.0 and s.mean_[2] == 0.0 and s.scale_[2] == 1.0
    np.testing.assert_allclose(s.inverse(z), x, atol=1e-5)
    with pytest.raises(ValueError):
        Standardizer.from_arrays(np.zeros(2), np.array([1.0, 0.0]))


def test_cosine_schedule_is_adam_with_a_falling_learning_rate(rng):
    x, t = toy(rng, 200)
    nets = [small_net(np.random.default_rng(5)) for _ in range(2)]
    steps, lr = 6, 0.02
    Trainer(steps=steps, lr=lr, schedule="cosine", eval_every=steps).fit(nets[0], x, t, rng=rng)
    net = nets[1]
    opt = Adam(net.n_params, lr=lr)
    ws = net.workspace(200)
    ws.set_inputs(x)
    grad = np.empty_like(net.theta)
    thetas = []
    for s in range(steps):
        opt.lr = 0.5 * lr * (1.0 + np.cos(np.pi * s / steps))
        _sse_and_grad(net, ws, t, grad, 2.0 / 200)
        opt.step(net.theta, grad)
        thetas.append(net.theta.copy())
    # the trainer keeps the best weights: one of the steps of the manual run
    assert any(np.allclose(nets[0].theta, th, rtol=1e-5, atol=1e-6) for th in thetas)
    assert not np.allclose(thetas[-1], thetas[-2])


def test_patience_stops_training_and_keeps_the_best_weights(rng):
    x, t = toy(rng, 200)
    xv, tv = toy(rng, 100)
    net = small_net(rng)
    tr = Trainer(steps=20_000, lr=0.05, eval_every=10, patience=100).fit(net, x, t, xv, tv, rng=rng)
    assert tr.steps_ < 20_000 and tr.steps_ % 10 == 0
    assert tr.history_val_.size == tr.steps_ // 10
    assert sse(net, xv, tv) / 100 == pytest.approx(tr.history_val_.min(), rel=1e-6)


def test_a_progress_report_returning_true_ends_training_there(rng):
    x, t = toy(rng, 200)
    net = small_net(rng)
    tr = Trainer(steps=1000, eval_every=10, on_eval=lambda step, *_: step >= 300).fit(net, x, t, rng=rng)
    assert tr.steps_ == 300 and tr.history_train_.size == 30


def test_without_keep_best_the_last_weights_stay_and_no_loss_is_evaluated(rng, monkeypatch):
    from fricli.numerics.nn import training

    x, t = toy(rng, 200)
    kept, last = small_net(rng), small_net(rng)
    last.theta[...] = kept.theta
    Trainer(steps=200, lr=0.05, eval_every=10).fit(kept, x, t, rng=np.random.default_rng(1))

    def no_evaluation(self):
        raise AssertionError("the loss was evaluated")

    monkeypatch.setattr(training.Evaluator, "sse", no_evaluation)
    thetas = []
    tr = Trainer(steps=200, lr=0.05, eval_every=10, keep_best=False,
                 on_eval=lambda *_: thetas.append(last.theta.copy())).fit(last, x, t, rng=np.random.default_rng(1))
    np.testing.assert_array_equal(last.theta, thetas[-1])   # the weights of the last step
    assert tr.history_train_.size == 20 and tr.steps_ == 200
    assert any(np.array_equal(kept.theta, th) for th in thetas)   # the same run, which kept its best


def test_unknown_schedule_refused():
    with pytest.raises(ValueError, match="schedule"):
        Trainer(steps=10, schedule="linear")


def test_a_grouped_workspace_refuses_gathered_inputs():
    from fricli.models.dissipative import DissipativeFriction

    # ten equal columns: (3 inputs) for the plain network, (2 inputs + 2 aux rows) for the headed one
    x = np.tile(np.array([[0.5], [1.0], [0.3], [0.2]], dtype=np.float32), (1, 10))
    for net, rows in ((Network(3, [(4, acts.ELU())]), 3), (DissipativeFriction().new_network(), 4)):
        ws = net.workspace_for(x[:rows])
        assert ws.groups is not None
        with pytest.raises(ValueError, match="grouped"):
            ws.take_inputs(x[:rows], np.arange(10))
