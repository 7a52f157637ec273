"""Publish a merged dataset (frames, videos, eval records, scores, card) to the Hugging Face Hub.

One commit carries everything (``upload_folder`` of the dataset root, whose ``README.md``
is already the card with the score table), then the LeRobot codebase-version tag that
``LeRobotDataset(repo_id)`` resolves. So a push that fails midway never leaves a dataset on
the Hub whose scores and frames disagree. (LeRobot's own ``push_to_hub`` makes a second
commit for a regenerated card.)

The token comes from the environment (``HF_TOKEN`` or the huggingface_hub login), the
endpoint from ``HF_ENDPOINT``. A failed push leaves every local file as it was and returns the
reason, which ``molmo-eval`` records in ``results.json`` (``push``) and turns into a non-zero
exit. The token never appears in a message: it is masked out of any error text.
"""

from __future__ import annotations

import contextlib
import logging
import os
from pathlib import Path

log = logging.getLogger(__name__)


def _mask(text: str) -> str:
    from huggingface_hub import get_token

    for secret in {os.environ.get("HF_TOKEN"), os.environ.get("HUGGING_FACE_HUB_TOKEN"), get_token()}:
        if secret:
            text = text.replace(secret, "***")
    return text


def failure_line(exc: BaseException) -> str:
    """A failed push's reason: the exception's first line, with any Hub token masked."""
    return (_mask(f"{type(exc).__name__}: {exc}").splitlines() or [type(exc).__name__])[0]


def push_dataset(root: Path, repo_id: str, *, private: bool = False) -> str | None:
    """Push the LeRobot dataset at ``root`` as dataset repo ``repo_id``; the reason (one line) if it failed."""
    from huggingface_hub import HfApi
    from huggingface_hub.errors import RevisionNotFoundError
    from lerobot.datasets.dataset_metadata import CODEBASE_VERSION

    root = Path(root)
    try:
        if not (root / "meta" / "info.json").is_file():
            raise FileNotFoundError(f"{root} is not a LeRobot dataset (no meta/info.json)")
        api = HfApi()
        api.create_repo(repo_id, repo_type="dataset", private=private, exist_ok=True)
        commit = api.upload_folder(repo_id=repo_id, repo_type="dataset", folder_path=root,
                                   ignore_patterns=["images/*", ".*"],
                                   commit_message="molmo_lerobot: evaluation rollouts and scores")
        with contextlib.suppress(RevisionNotFoundError):
            api.delete_tag(repo_id, tag=CODEBASE_VERSION, repo_type="dataset")
        api.create_tag(repo_id, tag=CODEBASE_VERSION, revision=commit.oid, repo_type="dataset")
    except Exception as exc:  # a push must never cost the local results
        reason = failure_line(exc)
        log.warning("push of %s to the Hub as %s failed; local files are intact: %s", root, repo_id, reason)
        return reason
    log.info("pushed %s to the Hub as dataset %s", root, repo_id)
    return None
