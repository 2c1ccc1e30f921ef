"""Every conformance check over every registered plugin, third-party ones included."""

from nlosfw.testing import parametrize_with_checks


@parametrize_with_checks()
def test_conformance(spec, check):
    check(spec)
