import warnings

import numpy as np
import pytest

from tactrec.database import build_entries


@pytest.fixture(scope="session")
def table1():
    """The four surfaces of paper Table 1 with their lookup tables."""
    return build_entries(["paper-table1"])


@pytest.fixture(scope="session")
def scans():
    """Four YCB scans (banana, mug, pear, hammer) with their lookup tables."""
    return build_entries(["banana", "mug", "pear", "hammer"])


@pytest.fixture(autouse=True)
def _quiet_numpy():
    with warnings.catch_warnings():
        warnings.simplefilter("error", category=DeprecationWarning)
        with np.errstate(all="warn"):
            yield
