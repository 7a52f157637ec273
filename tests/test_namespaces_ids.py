"""Dataset ids and their namespaces with Minari's rules."""

from __future__ import annotations

import pytest

from molmo_lerobot import namespaces as ns
from molmo_lerobot.namespaces import NamespaceError


@pytest.mark.parametrize("good", ["ab", "molmo/pick", "org-1/sub_2/deeper", "a_b"])
def test_valid_namespaces(good):
    ns.validate_namespace(good)


@pytest.mark.parametrize("bad", ["", "a", "/abs", "trailing/", "dou//ble", "sp ace", "dot.ted", "../up"])
def test_invalid_namespaces(bad):
    with pytest.raises(NamespaceError, match="malformed namespace"):
        ns.validate_namespace(bad)


def test_no_namespace_is_a_type_error_as_minaris():
    with pytest.raises(TypeError, match="cannot be None"):
        ns.validate_namespace(None)


def test_parse_dataset_ids():
    assert ns.parse_dataset_id("molmo/pick/run-v1") == ("molmo/pick", "run-v1")
    assert ns.parse_dataset_id("solo") == (None, "solo")
    for bad in ("ns/", "/x", "ns/..", "n s/x", "ns/.hidden", "a//b/x"):
        with pytest.raises(NamespaceError):
            ns.parse_dataset_id(bad)
