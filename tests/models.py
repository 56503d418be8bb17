"""Small untrained learned models for tests that need networks but not training."""

from __future__ import annotations

import torch

from usd_garment.body.fingerprint import model_fingerprint
from usd_garment.body.model import BodyModel
from usd_garment.garment.template import GarmentTemplate
from usd_garment.generative.vae import DecoderConfig, GarmentVAE
from usd_garment.methods.learned_model import LearnedModel, Member
from usd_garment.regressor.gru import GarmentRegressor
from usd_garment.regressor.pose_code import PoseCodec


def untrained_model(body: BodyModel, template: GarmentTemplate, seed: int = 0) -> LearnedModel:
    """Small networks for ``template`` drawn with ``seed``, untrained, decoding to within a few
    cm of its rest shape."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        decoder = DecoderConfig(kind="basis", hidden=[16], basis_size=8)
        vae = GarmentVAE(len(template.vertices), encoder_hidden=None, decoder=decoder)
        vae.mean.copy_(torch.as_tensor(template.vertices))
        vae.std.fill_(0.01)
        member = Member(
            vae=vae.eval(),
            pose_codec=PoseCodec(hidden=16).eval(),
            regressor=GarmentRegressor(hidden=(8,)).eval(),
        )
        return LearnedModel(
            [member],
            garment=template.name,
            lod=template.lod,
            vertices=len(template.vertices),
            version="test",
            body_name=body.name,
            body_fingerprint=model_fingerprint(body),
        )
