"""Random-init LeRobot PI0 / PI0.5 checkpoints for throughput work: no weights, no Hub.

``save_random_pi0(out, size=…)`` writes what ``PI0Policy.save_pretrained`` and LeRobot's
processors write (``config.json``, ``model.safetensors``, the pre/post-processor JSON and
state files) plus a stand-in tokenizer under ``tokenizer/`` in the layout of a Hugging Face
tokenizer repo (``tokenizer.json``, ``tokenizer_config.json``): the real PaliGemma tokenizer is a
gated Hub download. The preprocessor names that directory (absolute path), so the checkpoint
loads where it was made. The stand-in is byte-level (every prompt encodes, ids < 260, Gemma's
special-token ids); prompts are padded to ``tokenizer_max_length`` as with the real one, so the
model's work per call is the same.

Sizes: ``full`` is LeRobot's own architecture (PaliGemma 3B: SigLIP-So400m, Gemma 2B, the
300M action expert) and the checkpoint is a plain ``pi0`` one. Any other size keeps PI0's
structure and sequence lengths (224² images in 14² patches = 256 tokens per camera, 48 prompt
tokens, a 50-step chunk, 10 denoising steps) with narrower, shallower towers and a small
vocabulary. LeRobot's ``PI0Config`` only knows the ``gemma_2b`` / ``gemma_300m`` variants and
fixes the vision tower, so the sizes are recorded in ``molmo_pi0_dims.json`` and
:func:`scaled_architecture` applies them while the model is built; ``policy=pi0`` does this when
it loads such a checkpoint. (Plain ``policy=lerobot`` builds the full model and its weight check
refuses the checkpoint.)

CLI: ``python -m molmo_pi0.random_init OUT [--size small|full] [--type pi0|pi05] [--seed N]``.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict

DIMS_FILE = "molmo_pi0_dims.json"
TOKENIZER_DIR = "tokenizer"
#: Gemma's special tokens at Gemma's ids
SPECIAL_TOKENS = ("<pad>", "<eos>", "<bos>", "<unk>")
PolicyKind = Literal["pi0", "pi05"]


class GemmaDims(BaseModel):
    """One Gemma tower, as LeRobot's ``GemmaConfig`` (openpi's ``gemma.Config``)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    width: int
    depth: int
    mlp_dim: int
    num_heads: int
    num_kv_heads: int
    head_dim: int


class VisionDims(BaseModel):
    """The SigLIP tower (patch size and image size stay PaliGemma's: 14, 224)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    width: int
    depth: int
    mlp_dim: int
    num_heads: int


class Pi0Dims(BaseModel):
    """A PI0 architecture: each Gemma variant name's tower, the vision tower, the vocabulary."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    variants: dict[str, GemmaDims]  # keyed by PI0Config's variant names (gemma_2b, gemma_300m)
    vision: VisionDims
    vocab_size: int


#: Sizes other than ``full`` (LeRobot's own). ``small``: the VLM and the expert share depth,
#: heads and head size (their attention is joint, as in PI0), ~5 M parameters in all.
SIZES: dict[str, Pi0Dims] = {
    "small": Pi0Dims(
        variants={"gemma_2b": GemmaDims(width=256, depth=2, mlp_dim=1024, num_heads=4, num_kv_heads=1, head_dim=64),
                  "gemma_300m": GemmaDims(width=128, depth=2, mlp_dim=512, num_heads=4, num_kv_heads=1, head_dim=64)},
        vision=VisionDims(width=192, depth=2, mlp_dim=768, num_heads=3),
        vocab_size=1024,
    ),
}
SIZE_NAMES = ("full", *SIZES)

_BUILD_LOCK = threading.Lock()


def read_dims(path: str | Path) -> tuple[PolicyKind, Pi0Dims] | None:
    """The scaled architecture a checkpoint directory records, or None (LeRobot's own, or not a local dir)."""
    file = Path(path) / DIMS_FILE
    if not file.is_file():
        return None
    doc = json.loads(file.read_text())
    try:
        return doc["type"], Pi0Dims.model_validate(doc["dims"])
    except (KeyError, ValueError) as exc:
        raise ValueError(f"{file}: not a molmo_pi0 dims file ({type(exc).__name__}: {exc})") from None


@contextlib.contextmanager
def scaled_architecture(kind: PolicyKind, dims: Pi0Dims | None) -> Iterator[None]:
    """While open, LeRobot's ``kind`` model (``pi0`` / ``pi05``) is built with ``dims`` (None: unchanged).

    Patches the three names its ``PaliGemmaWithExpertModel`` builds from (``get_gemma_config``,
    the PaliGemma and expert Gemma classes) in LeRobot's modeling module, under a lock.
    """
    if dims is None:
        yield
        return
    modeling = importlib.import_module(f"lerobot.policies.{kind}.modeling_{kind}")
    names = ("get_gemma_config", "PaliGemmaForConditionalGenerationWithPiGemma", "PiGemmaForCausalLM")
    with _BUILD_LOCK:
        saved = {name: getattr(modeling, name) for name in names}

        def get_gemma_config(variant: str) -> Any:
            if variant not in dims.variants:
                raise ValueError(f"{kind} variant {variant!r} has no dims here (known: {sorted(dims.variants)})")
            return modeling.GemmaConfig(**dims.variants[variant].model_dump())

        def paligemma(config: Any) -> Any:
            vision, text = config.vision_config, config.text_config
            vision.hidden_size, vision.num_hidden_layers = dims.vision.width, dims.vision.depth
            vision.intermediate_size, vision.num_attention_heads = dims.vision.mlp_dim, dims.vision.num_heads
            vision.projection_dim = text.hidden_size  # the projector maps image tokens to the VLM's width
            text.vocab_size = vision.vocab_size = dims.vocab_size
            config.image_token_index = dims.vocab_size
            return saved["PaliGemmaForConditionalGenerationWithPiGemma"](config=config)

        def expert(config: Any) -> Any:
            config.vocab_size = dims.vocab_size  # its embedding is dropped after construction
            return saved["PiGemmaForCausalLM"](config=config)

        try:
            for name, value in zip(names, (get_gemma_config, paligemma, expert), strict=True):
                setattr(modeling, name, value)
            yield
        finally:
            for name, value in saved.items():
                setattr(modeling, name, value)


def save_standin_tokenizer(out: str | Path, model_max_length: int = 48) -> Path:
    """A byte-level BPE tokenizer with Gemma's special ids (pad 0, eos 1, bos 2, unk 3), ``<bos>``
    prepended as PaliGemma's tokenizer does, saved as a Hugging Face tokenizer directory."""
    from tokenizers import Tokenizer, decoders, models, pre_tokenizers, processors
    from transformers import PreTrainedTokenizerFast

    vocab = {token: i for i, token in enumerate(SPECIAL_TOKENS)}
    for char in sorted(pre_tokenizers.ByteLevel.alphabet()):
        vocab[char] = len(vocab)
    tok = Tokenizer(models.BPE(vocab=vocab, merges=[], unk_token="<unk>"))
    tok.pre_tokenizer = pre_tokenizers.ByteLevel(add_prefix_space=False)
    tok.decoder = decoders.ByteLevel()
    tok.post_processor = processors.TemplateProcessing(single="<bos> $A", pair="<bos> $A $B",
                                                       special_tokens=[("<bos>", vocab["<bos>"])])
    fast = PreTrainedTokenizerFast(tokenizer_object=tok, pad_token="<pad>", eos_token="<eos>", bos_token="<bos>",
                                   unk_token="<unk>", model_max_length=model_max_length)
    out = Path(out)
    fast.save_pretrained(out)
    return out


def save_random_pi0(out: str | Path, size: str = "small", kind: PolicyKind = "pi0", seed: int = 0,
                    cameras: tuple[str, ...] = ("exterior", "wrist"), state_dim: int = 8, action_dim: int = 8,
                    dtype: Literal["float32", "bfloat16"] = "float32") -> Path:
    """Write a random-init ``kind`` checkpoint of ``size`` to ``out`` (see the module docstring).

    Inputs: one 224² image feature ``observation.images.<camera>`` per camera, ``observation.state``
    (``state_dim``); output ``action`` (``action_dim``). Normalization statistics are the identity
    (mean 0, std 1, quantiles ±1). The same arguments give the same weights.
    """
    import torch
    from lerobot.configs.types import FeatureType, PolicyFeature
    from lerobot.policies.factory import get_policy_class

    if size not in SIZE_NAMES:
        raise ValueError(f"size={size!r}: expected one of {list(SIZE_NAMES)}")
    dims = SIZES.get(size)
    config_mod = importlib.import_module(f"lerobot.policies.{kind}.configuration_{kind}")
    config_cls = getattr(config_mod, "PI0Config" if kind == "pi0" else "PI05Config")
    features = {f"observation.images.{c}": PolicyFeature(FeatureType.VISUAL, (3, 224, 224)) for c in cameras}
    features["observation.state"] = PolicyFeature(FeatureType.STATE, (state_dim,))
    config = config_cls(input_features=features,
                        output_features={"action": PolicyFeature(FeatureType.ACTION, (action_dim,))},
                        dtype=dtype, device="cpu")
    out = Path(out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(seed)
    with scaled_architecture(kind, dims):
        policy = get_policy_class(kind)(config)
    policy.save_pretrained(out)
    tokenizer = save_standin_tokenizer(out / TOKENIZER_DIR, config.tokenizer_max_length)
    stats = {key: _identity_stats(n) for key, n in (("observation.state", state_dim), ("action", action_dim))}
    for pipeline in _processors(kind, config, stats, tokenizer):
        pipeline.save_pretrained(out)
    if dims is not None:
        (out / DIMS_FILE).write_text(json.dumps({"type": kind, "size": size, "dims": dims.model_dump()}, indent=1))
    return out


def _identity_stats(n: int) -> dict[str, Any]:
    import torch

    zeros, ones = torch.zeros(n), torch.ones(n)
    return {"mean": zeros, "std": ones, "min": -ones, "max": ones, "q01": -ones, "q99": ones,
            "q10": -ones, "q90": ones}


def _processors(kind: PolicyKind, config: Any, stats: dict[str, Any], tokenizer: Path) -> tuple[Any, Any]:
    """LeRobot's own pre/post-processors for ``kind``, its tokenizer step reading ``tokenizer``."""
    processor_mod = importlib.import_module(f"lerobot.policies.{kind}.processor_{kind}")
    step_cls = processor_mod.TokenizerProcessorStep

    def tokenizer_step(**kwargs: Any) -> Any:
        return step_cls(**{**kwargs, "tokenizer_name": str(tokenizer)})

    with _BUILD_LOCK:
        processor_mod.TokenizerProcessorStep = tokenizer_step
        try:
            return getattr(processor_mod, f"make_{kind}_pre_post_processors")(config, dataset_stats=stats)
        finally:
            processor_mod.TokenizerProcessorStep = step_cls


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m molmo_pi0.random_init", description=__doc__.splitlines()[0])
    parser.add_argument("out")
    parser.add_argument("--size", default="small", choices=SIZE_NAMES)
    parser.add_argument("--type", default="pi0", choices=("pi0", "pi05"))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--dtype", default="float32", choices=("float32", "bfloat16"))
    args = parser.parse_args(argv)
    out = save_random_pi0(args.out, size=args.size, kind=args.type, seed=args.seed, dtype=args.dtype)
    print(f"{args.type} ({args.size}, random init, seed {args.seed}) -> {out}: policy=pi0 policy.path={out}")


if __name__ == "__main__":
    main()
