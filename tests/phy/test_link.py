"""FlatLink and one-tap equalisation: closed forms and what the receiver is told."""

import pytest
import torch

import phy


def test_zf_inverts_the_channel_exactly_without_noise():
    h = torch.tensor([[0.5 + 0.5j, -2.0 + 0.1j]], dtype=torch.complex64)
    x = torch.tensor([[1 + 1j, -1 + 0j]], dtype=torch.complex64)
    x_hat, nv = phy.equalize(h * x, h, 0.1, "zf")
    torch.testing.assert_close(x_hat, x)
    torch.testing.assert_close(nv, 0.1 / h.abs().pow(2))


def test_mmse_closed_form_by_hand():
    h = torch.tensor([[1.0 + 1.0j]], dtype=torch.complex64)  # |h|^2 = 2
    y = torch.tensor([[2.0 + 0.0j]], dtype=torch.complex64)
    x_hat, nv = phy.equalize(y, h, 0.5, "mmse")
    # conj(h) y / (|h|^2 + N0) = (1 - 1j) * 2 / 2.5
    torch.testing.assert_close(x_hat, torch.tensor([[0.8 - 0.8j]], dtype=torch.complex64))
    torch.testing.assert_close(nv, torch.tensor([[0.5 / 2.5]]))


def test_post_equalization_snr():
    h = torch.tensor([[2.0 + 0j, 0.5j]], dtype=torch.complex64)
    snr = phy.post_equalization_snr(h, torch.tensor([0.1]), estimation_error_var=0.1)
    torch.testing.assert_close(snr, torch.tensor([[4.0 / 0.2, 0.25 / 0.2]]))


@pytest.mark.parametrize("equalizer", ["mmse", "zf"])
@pytest.mark.parametrize("name", ["awgn", "rayleigh", "rayleigh_fast", "rician"])
def test_reported_noise_var_matches_measured_error(name, equalizer):
    """The link tells the truth: mean reported noise_var == measured E|x_hat - x|^2."""
    g = torch.Generator().manual_seed(0)
    x = phy.power_normalize(torch.randn(200, 2000, dtype=torch.complex64, generator=g))
    link = phy.FlatLink(phy.make_channel(name), csi="perfect", equalizer=equalizer)
    out = link(x, 10.0, generator=g)
    assert out.x_hat.shape == x.shape and out.noise_var.shape == x.shape
    err = (out.x_hat - x).abs().pow(2)
    if equalizer == "zf" and name == "rayleigh_fast":
        # E[1/|h|^2] diverges for Rayleigh: compare where the channel is not in a deep fade
        keep = out.noise_var < 1.0
        err, nv = err[keep], out.noise_var[keep]
    else:
        nv = out.noise_var
    assert abs(err.mean().item() / nv.mean().item() - 1) < 0.05


def test_link_is_differentiable():
    x = phy.power_normalize(torch.randn(2, 64, dtype=torch.complex64)).requires_grad_(True)
    out = phy.FlatLink(phy.RayleighFading("block"))(
        x, 0.0, generator=torch.Generator().manual_seed(1)
    )
    out.x_hat.abs().pow(2).sum().backward()
    assert x.grad is not None and x.grad.abs().sum() > 0


def test_no_csi_passes_y_through():
    g = torch.Generator().manual_seed(3)
    x = torch.ones(1, 8, dtype=torch.complex64)
    ch = phy.RayleighFading()
    out = phy.FlatLink(ch, csi="none")(x, 10.0, generator=g)
    ref = ch(x, 10.0, generator=torch.Generator().manual_seed(3))
    torch.testing.assert_close(out.x_hat, ref.y)
    torch.testing.assert_close(out.noise_var, torch.full((1, 8), 0.1))


def test_bad_link_arguments():
    with pytest.raises(ValueError, match="csi must be one of"):
        phy.FlatLink(phy.AWGN(), csi="ls")
    with pytest.raises(ValueError, match="equalizer must be one of"):
        phy.FlatLink(phy.AWGN(), equalizer="ml")
    with pytest.raises(ValueError, match=r"\[batch, num_symbols\]"):
        phy.FlatLink(phy.AWGN())(torch.ones(1, 2, 3, dtype=torch.complex64), 0.0)


@pytest.mark.gpu
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_links_run_on_cuda_with_a_cuda_generator():
    dev = "cuda"
    g = torch.Generator(device=dev).manual_seed(0)
    x = phy.power_normalize(torch.randn(4, 1000, dtype=torch.complex64, device=dev, generator=g))
    for link in (
        phy.FlatLink(phy.RicianFading(mode="fast")),
        phy.OFDMLink(phy.ResourceGrid(), phy.RayleighFading("block"), csi="ls"),
    ):
        out = link(x, 10.0, generator=g)
        assert out.x_hat.device.type == dev and out.noise_var.device.type == dev
        mse = (out.x_hat - x).abs().pow(2).mean().item()
        assert mse == pytest.approx(out.noise_var.mean().item(), rel=0.15)
