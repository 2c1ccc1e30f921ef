"""nlosfw's conformance kit, applied to this imager only."""

from nlosfw.testing import parametrize_with_checks


@parametrize_with_checks(names=["example_backprojection"])
def test_example_backprojection_conforms(spec, check):
    check(spec)
