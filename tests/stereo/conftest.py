"""Shared fixture of the stereo tests: the stereo_lab site's ``stereo`` section."""

import pytest
import yaml

SITE = "config/sites/stereo_lab.yaml"


@pytest.fixture(scope="module")
def cfg(request):
    """The ``stereo`` section of ``config/sites/stereo_lab.yaml``."""
    return yaml.safe_load((request.config.rootpath / SITE).read_text())["stereo"]
