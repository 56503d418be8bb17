"""The generative garment subspace: VAE shapes and configuration round trips, the loss terms
against obvious references, and short trainings on a synthetic sliding garment around a sphere
body (reconstruction improves, the self-supervised collision term empties the random decodings,
checkpoints resume)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
import trimesh

from usd_garment.canonical.dataset import CanonicalSet
from usd_garment.generative.losses import (
    COLLISION_EPSILON,
    UniformLaplacian,
    collision_loss,
    kl_loss,
    laplacian_loss,
    mesh_edges,
    reconstruction_loss,
)
from usd_garment.generative.vae import (
    OFFICIAL_DECODER,
    DecoderConfig,
    GarmentVAE,
    decoder_bytes,
    load_vae,
    num_parameters,
    save_vae,
)
from usd_garment.training.vae import VaeTrainConfig, split_frames, train_vae

BODY_RADIUS = 0.1
GAP = 2.5e-3
FRAMES = 32
SMALL_DECODER = DecoderConfig(kind="basis", hidden=(64,), basis_size=16)


class SphereBody:
    """The canonical body as a sphere: ``sdf(points (..., 3)) -> (...)`` (m)."""

    def sdf(self, points: torch.Tensor) -> torch.Tensor:
        return points.norm(dim=-1) - BODY_RADIUS


def sliding_set(sequences: int = 8, validation: int = 2, seed: int = 0) -> CanonicalSet:
    """A garment sliding on a sphere body: an icosphere (162 vertices) 2.5 mm outside the body
    with 4 smooth outward bumps, turned about the vertical axis by up to ±0.6 rad; every
    quantity a smooth function of time. Linear blends of two frames cut chords into the body,
    as a tight garment sliding over a shoulder does; the data itself never enters it."""
    rng = np.random.default_rng(seed)
    mesh = trimesh.creation.icosphere(subdivisions=2)
    unit = np.asarray(mesh.vertices)
    centres = rng.normal(size=(4, 3))
    centres /= np.linalg.norm(centres, axis=1, keepdims=True)
    kernel = np.exp(-((unit[:, None] - centres[None]) ** 2).sum(-1) / 0.3)  # (N, 4)
    t = np.arange(FRAMES)[:, None]
    frames = []
    for _ in range(sequences):
        a = 0.5 + 0.5 * np.sin(rng.uniform(0.05, 0.3, 5) * t + rng.uniform(0, 2 * np.pi, 5))
        radius = BODY_RADIUS + GAP + 0.01 * a[:, :4] @ kernel.T  # (T, N)
        angle = 0.6 * (2 * a[:, 4] - 1)
        x = unit[None] * radius[..., None]
        c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
        turned = np.stack([c * x[..., 0] + s * x[..., 2], x[..., 1], c * x[..., 2] - s * x[..., 0]])
        frames.append(np.moveaxis(turned, 0, -1))
    canonical = np.concatenate(frames).astype(np.float32)
    total = len(canonical)
    return CanonicalSet(
        canonical=canonical,
        frame_offsets=np.arange(0, total + 1, FRAMES),
        betas=np.zeros((sequences, 10), np.float32),
        pose=np.zeros((total, 24, 3), np.float32),
        trans=np.zeros((total, 3), np.float32),
        fps=np.full(sequences, 30.0, np.float32),
        error=np.zeros(total, np.float32),
        max_error=np.zeros(total, np.float32),
        template=(unit * (BODY_RADIUS + GAP)).astype(np.float32),
        faces=np.asarray(mesh.faces, dtype=np.int32),
        sources=[f"seq{s}" for s in range(sequences)],
        splits=["validation" if s < validation else "train" for s in range(sequences)],
    )


def small_config(**changes) -> VaeTrainConfig:
    values = dict(
        epochs=15, batch_size=32, lr=3e-3, lr_decay=1.0, encoder_hidden=(64,),
        decoder=SMALL_DECODER, eval_random=256,
    )  # fmt: skip
    return VaeTrainConfig(**(values | changes))


@pytest.fixture(scope="module")
def data() -> CanonicalSet:
    return sliding_set()


@pytest.fixture(autouse=True)
def one_thread():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


# -- the model -----------------------------------------------------------------------------


@pytest.mark.parametrize(
    "decoder", [SMALL_DECODER, DecoderConfig(kind="mlp", hidden=(32, 32), layer_norm=False)]
)
def test_shapes_and_statistics(data, decoder):
    x = torch.as_tensor(data.canonical[:5])
    model = GarmentVAE(x.shape[1], encoder_hidden=(32,), decoder=decoder)
    model.set_statistics(torch.as_tensor(data.canonical))
    mu, logvar = model.encode(x)
    assert mu.shape == logvar.shape == (5, 25)
    assert model.decode(mu).shape == (5, 162, 3)
    model.train()
    rec, mu2, logvar2 = model(x, generator=torch.Generator().manual_seed(0))
    assert rec.shape == x.shape and mu2.shape == (5, 25) and logvar2.shape == (5, 25)
    model.eval()
    torch.testing.assert_close(model(x)[0], model.decode(mu))  # evaluation decodes μ
    torch.testing.assert_close(model.mean, torch.as_tensor(data.canonical).mean(0))
    assert float(model.std.min()) > 0
    torch.testing.assert_close(model.denormalise(model.normalise(x)), x)


def test_basis_starts_at_principal_components(data):
    """With the PCA start, the basis spans the data: projecting the normalised training frames
    onto it leaves little (16 components of a 2-parameter family plus 4 bumps)."""
    x = torch.as_tensor(data.canonical)
    model = GarmentVAE(x.shape[1], encoder_hidden=(8,), decoder=SMALL_DECODER)
    model.set_statistics(x)
    xn = model.normalise(x).flatten(1)
    xn = xn - xn.mean(0)
    q, _ = torch.linalg.qr(model.decoder.basis.weight.detach().double())  # (3N, K)
    xn = xn.T.double()
    residual = (xn - q @ (q.T @ xn)).norm() / xn.norm()
    assert residual < 1e-3


def test_official_decoder_size():
    """25 → 4×2000 → 3N with N = 4,405: ~39 M parameters, as the official inference code."""
    with torch.device("meta"):
        model = GarmentVAE(4405, encoder_hidden=(8,), decoder=OFFICIAL_DECODER)
    assert 38.5e6 < num_parameters(model.decoder) < 39.5e6
    with torch.device("meta"):
        basis = GarmentVAE(4405, encoder_hidden=(8,), decoder=DecoderConfig(basis_size=64))
    assert decoder_bytes(basis) < 4e6  # float32
    statistics = 2 * 4405 * 3 * 4
    assert decoder_bytes(basis, 2) - statistics == (decoder_bytes(basis) - statistics) // 2


def test_config_round_trip(tmp_path, data):
    model = GarmentVAE(162, encoder_hidden=(16, 8), decoder=SMALL_DECODER)
    model.set_statistics(torch.as_tensor(data.canonical))
    config = json.loads(json.dumps(model.config()))
    rebuilt = GarmentVAE.from_config(config)
    rebuilt.load_state_dict(model.state_dict())
    assert rebuilt.config() == model.config()
    z = torch.randn(3, 25, generator=torch.Generator().manual_seed(1))
    torch.testing.assert_close(rebuilt.decode(z), model.decode(z))

    save_vae(tmp_path / "vae.pt", model, {"note": "test"})
    stored = load_vae(tmp_path / "vae.pt")
    assert stored.metadata == {"note": "test"} and not stored.model.training
    torch.testing.assert_close(stored.model.decode(z), model.decode(z))

    train = small_config(decoder=DecoderConfig(kind="mlp", hidden=(8, 4)))
    assert VaeTrainConfig.from_dict(json.loads(json.dumps(train.to_dict()))) == train
    with pytest.raises(ValueError, match="decoder kind"):
        DecoderConfig(kind="pca")


def test_decoder_only_files(tmp_path, data):
    """What run time ships: the decoder and the statistics, optionally stored in float16."""
    model = GarmentVAE(162, encoder_hidden=(64,), decoder=SMALL_DECODER)
    model.set_statistics(torch.as_tensor(data.canonical))
    z = torch.randn(4, 25, generator=torch.Generator().manual_seed(2))
    save_vae(tmp_path / "full.pt", model)
    save_vae(tmp_path / "dec.pt", model, encoder=False)
    save_vae(tmp_path / "dec16.pt", model, encoder=False, dtype=torch.float16)
    sizes = {name: (tmp_path / name).stat().st_size for name in ("full.pt", "dec.pt", "dec16.pt")}
    assert sizes["dec16.pt"] < 0.6 * sizes["dec.pt"] < 0.6 * sizes["full.pt"]
    decoder = load_vae(tmp_path / "dec.pt").model
    assert decoder.encoder is None and decoder.config()["encoder_hidden"] is None
    torch.testing.assert_close(decoder.decode(z), model.decode(z))
    half = load_vae(tmp_path / "dec16.pt").model
    assert half.mean.dtype == torch.float32
    with torch.no_grad():
        error = float((half.decode(z) - model.decode(z)).norm(dim=-1).max())
    assert error < 2e-5, error  # m
    with pytest.raises(RuntimeError, match="no encoder"):
        decoder.encode(torch.as_tensor(data.canonical[:1]))


def test_load_vae_refuses_other_files(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_vae(tmp_path / "missing.pt")
    (tmp_path / "junk.pt").write_bytes(b"not a torch file")
    with pytest.raises(ValueError, match="not a garment VAE"):
        load_vae(tmp_path / "junk.pt")


# -- the losses ----------------------------------------------------------------------------


def test_laplacian_matches_dense_reference(data):
    n = len(data.template)
    laplacian = UniformLaplacian(data.faces, n)
    adjacency = np.zeros((n, n))
    for a, b, c in data.faces:
        for i, j in ((a, b), (b, c), (c, a)):
            adjacency[i, j] = adjacency[j, i] = 1.0
    dense = np.eye(n) - adjacency / adjacency.sum(1, keepdims=True)
    x = torch.as_tensor(data.canonical[:3], dtype=torch.float64)
    expected = torch.as_tensor(np.einsum("ij,bjc->bic", dense, x.numpy()))
    torch.testing.assert_close(laplacian(x.float()).double(), expected, atol=1e-6, rtol=1e-5)
    torch.testing.assert_close(laplacian(x[0].float()).double(), expected[0], atol=1e-6, rtol=0)
    # translation-invariant, so the Laplacian term ignores a rigid shift
    shift = torch.tensor([0.01, -0.02, 0.03])
    assert laplacian_loss(x.float() + shift, x.float(), laplacian) < 1e-5
    assert len(mesh_edges(data.faces)) == 480  # icosphere(2): 162 + 320 − 2 edges


def test_laplacian_sums_as_along_the_batchs_vertex_dimension(data):
    # The sums run with the vertices leading (stop 93, three times as fast): the values and the
    # gradient of the sums along the batch's own vertex dimension, to the bit.
    laplacian = UniformLaplacian(data.faces, len(data.template))
    x = torch.as_tensor(data.canonical[:4], dtype=torch.float32).requires_grad_(True)
    grad = torch.rand(x.shape, generator=torch.Generator().manual_seed(0))
    gathered = x.index_select(1, laplacian.cols)
    along = (
        x
        - torch.zeros_like(x).index_add(1, laplacian.rows, gathered) * laplacian.inv_degree[:, None]
    )
    ours = laplacian(x)
    assert torch.equal(ours, along)
    assert torch.equal(*(torch.autograd.grad(y, x, grad)[0] for y in (ours, along)))


def test_reconstruction_and_kl_losses():
    x = torch.zeros(2, 4, 3)
    assert reconstruction_loss(x + 0.001, x).item() == pytest.approx(12 * 0.001)
    mu = torch.tensor([[0.5, -1.0], [0.0, 2.0]])
    logvar = torch.tensor([[0.0, -0.5], [0.3, 0.1]])
    reference = torch.distributions.kl_divergence(
        torch.distributions.Normal(mu, (0.5 * logvar).exp()), torch.distributions.Normal(0.0, 1.0)
    )
    torch.testing.assert_close(kl_loss(mu, logvar), reference.sum(-1).mean())
    assert kl_loss(torch.zeros(3, 25), torch.zeros(3, 25)).item() == 0.0


def test_collision_loss_zero_outside_positive_inside():
    body = SphereBody()
    direction = torch.nn.functional.normalize(torch.randn(2, 50, 3), dim=-1)
    outside = direction * (BODY_RADIUS + COLLISION_EPSILON + 1e-4)
    assert collision_loss(outside, body.sdf).item() == 0.0
    near = direction * (BODY_RADIUS + 0.5e-3)  # inside the ε margin: ε − 0.5 mm per vertex
    assert collision_loss(near, body.sdf).item() == pytest.approx(
        50 * (COLLISION_EPSILON - 0.5e-3), rel=1e-4
    )
    inside = (direction * (BODY_RADIUS - 0.01)).requires_grad_(True)
    loss = collision_loss(inside, body.sdf)
    assert loss.item() == pytest.approx(50 * (COLLISION_EPSILON + 0.01), rel=1e-4)
    loss.backward()
    outward = (inside.grad * direction).sum(-1)  # a descent step moves every vertex outwards
    assert bool((outward < 0).all())
    assert collision_loss(inside, body.sdf, epsilon=0.02).item() > loss.item()


def test_collision_loss_with_body_fields():
    """The real canonical body SDF: the T-shirt template lies outside, the template shrunk to
    60 % about its centre reaches into the body."""
    from usd_garment.fields.body_fields import load_body_fields
    from usd_garment.garment.library import load_template

    fields = load_body_fields()
    x = torch.as_tensor(load_template("tshirt", "low").vertices)[None]
    assert collision_loss(x, fields.sdf).item() == 0.0
    centre = x.mean(1, keepdim=True)
    assert collision_loss(centre + 0.6 * (x - centre), fields.sdf).item() > 0.0


def test_collision_loss_takes_the_gradient_of_one_lookup_everywhere():
    """The loss looks up the vertices more than ε outside without a gradient (stop 93): the
    same loss and the same gradient, to the bit, as one lookup with a gradient everywhere."""
    from usd_garment.fields.body_fields import load_body_fields
    from usd_garment.garment.library import load_template

    fields = load_body_fields()
    x = torch.as_tensor(load_template("tshirt", "low").vertices)[None]
    centre = x.mean(1, keepdim=True)
    x = torch.cat([centre + s * (x - centre) for s in (0.7, 0.9, 1.0)])  # (3, N, 3)
    ours = x.clone().requires_grad_(True)
    loss = collision_loss(ours, fields.sdf)
    loss.backward()
    whole = x.clone().requires_grad_(True)
    reference = (COLLISION_EPSILON - fields.sdf(whole)).clamp_min(0.0).sum(-1).mean()
    reference.backward()
    near = fields.sdf(x) <= COLLISION_EPSILON
    assert 0 < int(near.sum()) < near.numel()  # vertices on both sides of ε
    assert torch.equal(loss, reference)
    assert torch.equal(ours.grad, whole.grad)


# -- training ------------------------------------------------------------------------------


def test_split_frames(data):
    assert len(split_frames(data, "validation")) == 2 * FRAMES
    assert len(split_frames(data, "train")) == 6 * FRAMES
    assert len(split_frames(data, "test")) == 0


def test_training_reduces_reconstruction_loss(data):
    calls = []
    model, history = train_vae(
        data, small_config(epochs=10), fields=SphereBody(),
        progress=lambda epoch, total, row: calls.append((epoch, total, row["rec"])),
    )  # fmt: skip
    rows = history["epochs"]
    assert [c[:2] for c in calls] == [(e, 10) for e in range(1, 11)]
    assert rows[-1]["rec"] < 0.3 * rows[0]["rec"]
    assert rows[-1]["val_rec_l1_mm"] < 0.5 * rows[0]["val_rec_l1_mm"]
    assert rows[-1]["val_rec_l1_mm"] < 1.5
    assert history["frames"] == {"train": 6 * FRAMES, "validation": 2 * FRAMES}
    assert history["validation_inside_pct"] == 0.0
    json.dumps(history)
    assert not model.training


def test_self_supervision_keeps_random_decodings_out(data):
    """The paper's ablation in small: with only the supervised collision term, decodings of
    random latents cut into the body (blends of turned frames); the self-supervised term takes
    them out at no cost in reconstruction."""
    body = SphereBody()
    _, without = train_vae(data, small_config(self_supervised=False), fields=body)
    _, full = train_vae(data, small_config(self_supervised=True), fields=body)
    _, none = train_vae(data, small_config(collision=False), fields=body)
    a, b, c = without["epochs"][-1], full["epochs"][-1], none["epochs"][-1]
    assert c["val_rand_inside_pct"] > 20.0
    assert a["val_rand_inside_pct"] > 10.0
    assert b["val_rand_inside_pct"] < 0.1 * a["val_rand_inside_pct"]
    assert b["val_rec_inside_pct"] == 0.0
    assert b["val_rec_l1_mm"] < 1.5 * a["val_rec_l1_mm"]


def test_training_is_deterministic(data):
    config = small_config(epochs=2)
    first, h1 = train_vae(data, config, fields=SphereBody())
    second, h2 = train_vae(data, config, fields=SphereBody())
    for key, value in first.state_dict().items():
        assert torch.equal(value, second.state_dict()[key]), key
    drop = lambda rows: [{k: v for k, v in r.items() if k != "seconds"} for r in rows]  # noqa: E731
    assert drop(h1["epochs"]) == drop(h2["epochs"])


def test_resume_continues_the_epoch_count(tmp_path, data):
    path = tmp_path / "vae.ckpt"
    straight, _ = train_vae(data, small_config(epochs=4), fields=SphereBody())
    train_vae(data, small_config(epochs=2), fields=SphereBody(), checkpoint=path)
    resumed, history = train_vae(
        data, small_config(epochs=4), fields=SphereBody(), checkpoint=path, resume=True
    )
    assert [row["epoch"] for row in history["epochs"]] == [1, 2, 3, 4]
    assert history["config"]["epochs"] == 4
    for key, value in straight.state_dict().items():
        torch.testing.assert_close(resumed.state_dict()[key], value, rtol=0, atol=0)
    with pytest.raises(ValueError, match="other settings"):
        train_vae(data, small_config(epochs=5, lr=1e-2), fields=SphereBody(), checkpoint=path,
                  resume=True)  # fmt: skip
    fresh = tmp_path / "fresh.ckpt"  # resuming without a checkpoint starts from scratch
    _, history = train_vae(data, small_config(epochs=1), fields=SphereBody(), checkpoint=fresh,
                           resume=True)  # fmt: skip
    assert [row["epoch"] for row in history["epochs"]] == [1] and fresh.is_file()
    torch.save({"kind": "other"}, fresh)
    with pytest.raises(ValueError, match="not a VAE checkpoint"):
        train_vae(data, small_config(), fields=SphereBody(), checkpoint=fresh, resume=True)


def test_training_skips_what_the_simulation_flagged(data):
    """With ``skip_flagged_frames``, flagged training frames (here garbage) are left out of the
    statistics and the training: the run on the spoilt set fits as the run on the clean one
    (up to the summation order's rounding, which Adam's steps amplify), while without it the
    garbage adds half the reconstruction error again; a set without a record is refused."""
    spoilt = CanonicalSet(**{**vars(data), "canonical": data.canonical.copy()})
    spoilt.flagged = np.zeros(len(data.canonical), dtype=bool)
    spoilt.flagged[len(data.canonical) - 10 :] = True  # the last training sequence's end
    clean = CanonicalSet(**{**vars(spoilt), "canonical": data.canonical})
    spoilt.canonical[spoilt.flagged] *= 1.5
    config = small_config(epochs=2, skip_flagged_frames=True)
    first, history = train_vae(clean, config, fields=SphereBody())
    second, spoilt_history = train_vae(spoilt, config, fields=SphereBody())
    assert history["flagged_frames_skipped"] == 10
    assert history["frames"]["train"] == len(split_frames(data, "train")) - 10
    kept = split_frames(data, "train")[:-10]
    torch.testing.assert_close(second.mean, torch.as_tensor(data.canonical[kept]).mean(0))
    torch.testing.assert_close(second.std, first.std)
    rec = history["epochs"][-1]["rec"]
    assert spoilt_history["epochs"][-1]["rec"] == pytest.approx(rec, rel=0.01)
    _, plain = train_vae(spoilt, small_config(epochs=2), fields=SphereBody())
    assert plain["epochs"][-1]["rec"] > 1.2 * rec
    with pytest.raises(ValueError, match="flagged"):
        train_vae(data, config, fields=SphereBody())


def test_a_checkpoint_older_than_a_setting_resumes_with_its_default(tmp_path, data):
    path = tmp_path / "vae.ckpt"
    train_vae(data, small_config(epochs=1), fields=SphereBody(), checkpoint=path)
    state = torch.load(path, weights_only=True)
    del state["config"]["skip_flagged_frames"]
    torch.save(state, path)
    _, history = train_vae(
        data, small_config(epochs=2), fields=SphereBody(), checkpoint=path, resume=True
    )
    assert [row["epoch"] for row in history["epochs"]] == [1, 2]


def test_training_with_the_body_fields():
    """The real canonical body SDF (``BodyFields``) and the real low T-shirt: two epochs run,
    every figure is finite and nothing enters the body."""
    from usd_garment.fields.body_fields import load_body_fields
    from usd_garment.garment.library import load_template

    template = load_template("tshirt", "low")
    rng = np.random.default_rng(0)
    v = template.vertices.astype(np.float32)
    centres = v[rng.choice(len(v), 6, replace=False)]
    kernel = np.exp(-((v[:, None] - centres[None]) ** 2).sum(-1) / (2 * 0.08**2))  # (N, 6)
    coeffs = rng.uniform(-1, 1, size=(40, 6, 3)).astype(np.float32) * 0.004
    canonical = (v[None] + np.einsum("nk,tkc->tnc", kernel, coeffs)).astype(np.float32)
    data = CanonicalSet(
        canonical=canonical, frame_offsets=np.array([0, 10, 20, 30, 40]),
        betas=np.zeros((4, 10), np.float32), pose=np.zeros((40, 24, 3), np.float32),
        trans=np.zeros((40, 3), np.float32), fps=np.full(4, 30.0, np.float32),
        error=np.zeros(40, np.float32), max_error=np.zeros(40, np.float32), template=v,
        faces=template.faces, sources=["a", "b", "c", "d"],
        splits=["train", "train", "train", "validation"],
    )  # fmt: skip
    config = small_config(epochs=2, batch_size=10, self_supervised_batch=8, eval_random=32)
    _, history = train_vae(data, config, fields=load_body_fields())
    row = history["epochs"][-1]
    assert all(np.isfinite(value) for value in row.values())
    assert history["validation_inside_pct"] == 0.0
    assert row["val_rec_inside_pct"] == 0.0
