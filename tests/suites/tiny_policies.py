"""Tiny LeRobot policies at random init with an env suite's features (LeRobot's LIBERO datasets': two cameras, the
8-D state, the 7-D action; PushT's: ``observation.image``, the 2-D state and action; ALOHA's: the top camera, the
14-D state and action; MetaWorld's: ``observation.image``, the 4-D state and action), saved with their pre- and
post-processors where ``policy.path=`` (ours) and ``--policy.path=`` (``lerobot-eval``) load them. The image size
they declare is the caller's (a side, or (height, width)): the env's, or another one (``lerobot-eval`` hands a policy
the env's frames)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

#: each suite's LeRobot features: its cameras' image features, its state and action sizes
SUITE_FEATURES = {
    "libero": (("observation.images.image", "observation.images.image2"), 8, 7),
    "pusht": (("observation.image",), 2, 2),
    "aloha": (("observation.images.top",), 14, 14),
    "metaworld": (("observation.image",), 4, 4),
}


def _features(suite: str, image_size: int | tuple[int, int]) -> dict[str, Any]:
    from lerobot.configs.types import FeatureType, PolicyFeature

    images, state, action = SUITE_FEATURES[suite]
    height, width = (image_size, image_size) if isinstance(image_size, int) else image_size
    image = PolicyFeature(FeatureType.VISUAL, (3, height, width))
    return {"input_features": {**{key: image for key in images},
                               "observation.state": PolicyFeature(FeatureType.STATE, (state,))},
            "output_features": {"action": PolicyFeature(FeatureType.ACTION, (action,))}}


def save_act(path: Path, suite: str, image_size: int | tuple[int, int]) -> Path:
    """A tiny ACT (chunks of 4, no VAE: deterministic at inference) for ``suite``'s features; returns ``path``."""
    from lerobot.policies.act.configuration_act import ACTConfig
    from lerobot.policies.act.modeling_act import ACTPolicy

    cfg = ACTConfig(**_features(suite, image_size), pretrained_backbone_weights=None, dim_model=16, n_heads=2,
                    dim_feedforward=32, n_encoder_layers=1, n_decoder_layers=1, chunk_size=4, n_action_steps=4,
                    use_vae=False, device="cpu")
    return _save(path, ACTPolicy(cfg), cfg)


def save_diffusion(path: Path, suite: str, image_size: int) -> Path:
    """A tiny diffusion policy (2 observations, chunks of 4 from a horizon of 16, 20 DDPM steps drawing noise from
    torch's RNG, a 64² centre crop) for ``suite``'s features; returns ``path``."""
    from lerobot.policies.diffusion.configuration_diffusion import DiffusionConfig
    from lerobot.policies.diffusion.modeling_diffusion import DiffusionPolicy

    cfg = DiffusionConfig(**_features(suite, image_size), pretrained_backbone_weights=None, use_group_norm=True,
                          crop_shape=(64, 64), use_separate_rgb_encoder_per_camera=False,
                          spatial_softmax_num_keypoints=8, down_dims=(16, 32), kernel_size=3, n_groups=4,
                          diffusion_step_embed_dim=16, horizon=16, n_action_steps=4, n_obs_steps=2,
                          num_train_timesteps=20, device="cpu")
    return _save(path, DiffusionPolicy(cfg), cfg)


def _save(path: Path, policy: Any, cfg: Any) -> Path:
    from lerobot.policies.factory import make_pre_post_processors

    pre, post = make_pre_post_processors(cfg, dataset_stats=None)
    for obj in (policy, pre, post):
        obj.save_pretrained(path)
    return path
