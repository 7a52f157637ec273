"""Content hashes never change: episode digests seed camera and scene randomizations, episode seeds
seed the run, benchmark hashes identify the published files. The values below were computed on
main before the hashers became one module (``molmo_lerobot.hashing``)."""

from __future__ import annotations

import pytest

from molmo_lerobot.benchmark.load import load_benchmark
from molmo_lerobot.hashing import canonical_json, content_sha256, episode_digest
from molmo_lerobot.paths import data_path
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.runner.plan import episode_seed

#: (benchmark, episode index) -> (episode digest, seed at run seed 0, seed at run seed 3)
PINNED = {
    ("pick_v1", 0): ("8151d4a9670d9198b1f0e93b9cde3892d5f496e00383669b74c9249cb9d607fd", 1915829885, 2136952),
    ("pick_v1", 7): ("ab3f38463c0efbdb76aa72cb1e8ef70a6ac34cc89a15790c6a9cf16f8db647e1", 888259112, 363771854),
    ("open_v1", 0): ("ed2a32b00e383aa0653e9f0cb6169a6c40c96d8dd1fc13a782d3f5b16321594f", 1433164930, 122489180),
    ("open_v1", 7): ("04e84f5d668b814faec730a4e44a4738da6868ea6dd50b5183d7c28954a118e1", 1182241226, 2066561122),
    ("color_v1", 0): ("7b74f2d5bad0402d2a927f7757383e29b446ec9c86e72b55fa2bded79d08460b", 574707337, 819043445),
    ("color_v1", 7): ("ba027397e3300f8a526bd08b1ade6a67c85ffa853f205e35670a194e19dedbbb", 1862764596, 1471244473),
}
#: non-ASCII text, nesting, floats and nulls: where the spellings (separators, escapes) differ
ODD = {"prompt": "pick up the crème brûlée", "b": [1, 2.5, None], "a": {"z": True, "y": "ü"}}


@pytest.mark.parametrize(("name", "index"), sorted(PINNED))
def test_shipped_episodes_keep_their_digests_and_seeds(name, index):
    episode = load_benchmark(data_path("benchmarks") / name, Plugins()).episodes[index]
    digest, seed0, seed3 = PINNED[name, index]
    assert episode_digest(episode).hex() == digest
    assert episode_digest(episode.model_dump(mode="json")).hex() == digest
    assert episode_seed(0, episode.model_dump(mode="json")) == seed0
    assert episode_seed(3, episode.model_dump(mode="json", exclude_unset=False)) == seed3


def test_spellings_are_pinned():
    assert canonical_json(ODD) == '{"a":{"y":"ü","z":true},"b":[1,2.5,null],"prompt":"pick up the crème brûlée"}'
    assert content_sha256([ODD]).hex() == "3c9dd0c5b5bd4435d390c6cf1ccebe2c25ffa2858ee6e4e5ee185f9a68b7a6c6"
    assert episode_digest(ODD).hex() == "564c24a2bc1f349966bd96c2dd5ecc71fb2f9e0c5f96d97add0f8e7d7bcbbba6"
    assert episode_seed(0, ODD) == 850918098


def test_episode_seed_is_a_content_hash():
    """The run's episode seed is :func:`content_sha256` of the episode behind the run seed."""
    digest = content_sha256(ODD, prefix="0\n", ensure_ascii=True)
    assert int.from_bytes(digest[:4], "little") & 0x7FFFFFFF == episode_seed(0, ODD)
