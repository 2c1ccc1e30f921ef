"""nlosfw's conformance kit, applied to this plugin only."""

from nlosfw.testing import parametrize_with_checks


@parametrize_with_checks(names=["nearest"])
def test_nearest_conforms(spec, check):
    check(spec)
