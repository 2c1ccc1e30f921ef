"""nlosfw's conformance kit, applied to this network only."""

from nlosfw.testing import parametrize_with_checks


@parametrize_with_checks(names=["example_fourier_torch"])
def test_example_fourier_conforms(spec, check):
    check(spec)
