"""Dataset ids and their namespaces with Minari's rules."""

from __future__ import annotations

import pytest

from molmo_lerobot.assets import namespaces as ns
from molmo_lerobot.assets.namespaces import NamespaceError


@pytest.mark.parametrize("good", ["ab", "molmo/pick", "org-1/sub_2/deeper", "a_b"])
def test_valid_namespaces(good):
    assert ns.validate_namespace_id(good) == good


@pytest.mark.parametrize("bad", ["", "a", "/abs", "trailing/", "dou//ble", "sp ace", "dot.ted", "../up", None])
def test_invalid_namespaces(bad):
    with pytest.raises(NamespaceError, match="invalid namespace"):
        ns.validate_namespace_id(bad)


def test_parse_dataset_ids():
    assert ns.parse_dataset_id("molmo/pick/run-v1") == ("molmo/pick", "run-v1")
    assert ns.parse_dataset_id("solo") == (None, "solo")
    for bad in ("ns/", "/x", "ns/..", "n s/x"):
        with pytest.raises(NamespaceError):
            ns.parse_dataset_id(bad)
