"""Suite-wide fixtures."""

import random

import numpy as np
import pytest
import torch


@pytest.fixture(autouse=True)
def _seed_global_rngs():
    """Seed the global RNGs before every test: torch seeds its default generator differently in
    every process, so a test that draws from it (network initialisation, action sampling,
    minibatch shuffles) would otherwise see new numbers on every run."""
    torch.manual_seed(0)
    np.random.seed(0)
    random.seed(0)
