"""A tiny LeRobot ACT at random init with the features of LeRobot's LIBERO datasets (two cameras, the 8-D state,
the 7-D action), saved where ``policy.path=`` (ours) and ``--policy.path=`` (``lerobot-eval``) load it."""

from __future__ import annotations

from pathlib import Path


def save_libero_act(path: Path, image_size: int) -> Path:
    """Save the ACT, its pre- and post-processors to ``path`` for ``image_size``² camera images; returns ``path``."""
    from lerobot.configs.types import FeatureType, PolicyFeature
    from lerobot.policies.act.configuration_act import ACTConfig
    from lerobot.policies.act.modeling_act import ACTPolicy
    from lerobot.policies.factory import make_pre_post_processors

    image = PolicyFeature(FeatureType.VISUAL, (3, image_size, image_size))
    cfg = ACTConfig(input_features={"observation.images.image": image, "observation.images.image2": image,
                                    "observation.state": PolicyFeature(FeatureType.STATE, (8,))},
                    output_features={"action": PolicyFeature(FeatureType.ACTION, (7,))},
                    pretrained_backbone_weights=None, dim_model=16, n_heads=2, dim_feedforward=32, n_encoder_layers=1,
                    n_decoder_layers=1, chunk_size=4, n_action_steps=4, use_vae=False, device="cpu")
    pre, post = make_pre_post_processors(cfg, dataset_stats=None)
    for obj in (ACTPolicy(cfg), pre, post):
        obj.save_pretrained(path)
    return path
