"""Export tests run offline, with the datasets library's cache in a temporary folder."""

import os

import pytest


@pytest.fixture(scope="module", autouse=True)
def _local_only(tmp_path_factory):
    """No network, and the datasets library's cache in a temporary folder."""
    cache = tmp_path_factory.mktemp("hf_cache")
    old = {k: os.environ.get(k) for k in ("HF_HUB_OFFLINE", "HF_DATASETS_CACHE")}
    os.environ["HF_HUB_OFFLINE"] = "1"
    os.environ["HF_DATASETS_CACHE"] = str(cache)
    import datasets

    datasets.config.HF_DATASETS_CACHE = cache
    yield
    for k, v in old.items():
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v
