"""Every conformance check over every registered plugin, third-party ones included."""

import pytest

from nlosfw.common.errors import ConfigError, DataError
from nlosfw.plugins import load_plugins
from nlosfw.testing import parametrize_with_checks
from nlosfw.testing.checks_common import one_line_error


@parametrize_with_checks()
def test_conformance(spec, check):
    check(spec)


def test_one_line_error_accepts_only_the_expected_one_line_error():
    """The kit's error check fails on no error, two lines, an empty or a foreign error."""
    spec = load_plugins().registry.get("imager", "rsd")

    def raising(err):
        def call():
            raise err
        return call

    assert one_line_error(spec, "x", raising(DataError("bad voxels")), DataError) == "bad voxels"
    for call, message in ((lambda: None, "no error was raised"),
                          (raising(DataError("two\nlines")), "must be one line"),
                          (raising(DataError("")), "must be one line"),
                          (raising(ValueError("bare")), "raised ValueError"),
                          (raising(ConfigError("opt", "wrong kind")), "expected DataError")):
        with pytest.raises(AssertionError, match=message):
            one_line_error(spec, "x", call, DataError)
