"""Stage 5, evaluation: the protocol that scores a run, in one package.

* the splits (:mod:`~nlosfw.evaluation.splits`: spatial and spectral training and
  held-out samples of a phasor field; :mod:`~nlosfw.evaluation.count_splitting`: one
  capture's photon counts as two independent halves, A to train and B to score);
* field scores (:mod:`~nlosfw.evaluation.field_scores`): a prediction against the full
  field on the protocol's sets, and against the noise-free field;
* the held-out measurement of count splitting (:mod:`~nlosfw.evaluation.heldout`) with its
  noise floor (:mod:`~nlosfw.evaluation.noise_floor`) and excess; half A's full field
  scored against half B's is the ceiling;
* reconstruction scores (:mod:`~nlosfw.evaluation.image_scores`, the only importer of
  ``skimage.metrics``), and the reference-picture decision
  (:mod:`~nlosfw.evaluation.reference`);
* a score that cannot be computed is None with why (:class:`Scored`).

The run's stages compute every score through this package and hand them on in their
results; the metrics recorder only records them. The names in ``__all__`` are the public
API of this stage."""


from typing import TYPE_CHECKING

from nlosfw.common.lazy import lazy_exports

if TYPE_CHECKING:  # at run time each name loads on first use (nlosfw.common.lazy)
    from nlosfw.evaluation.count_splitting import CountSplit, check_count_split, split_counts
    from nlosfw.evaluation.field_scores import (
        denoising_errors,
        error_metrics,
        field_metrics,
        parameter_data_ratio,
    )
    from nlosfw.evaluation.heldout import (
        HeldoutMeasurement,
        HeldoutScores,
        heldout_measurement,
        heldout_scores,
    )
    from nlosfw.evaluation.image_scores import (
        amplitude,
        depth_rmse,
        image_metrics,
        ncc,
        normalise,
        psnr,
        reconstruction_scores,
        rmse,
        scored,
        ssim,
    )
    from nlosfw.evaluation.noise_floor import field_variance, kernel_power
    from nlosfw.evaluation.splits import (
        FieldSplit,
        SpatialPattern,
        SpatialSampling,
        SpectralSplit,
        heldout_frequency_indices,
        scattered_field,
        split_field,
    )
    from nlosfw.evaluation.undefined import Scored

__all__ = [
    "amplitude",
    "check_count_split",
    "CountSplit",
    "denoising_errors",
    "depth_rmse",
    "error_metrics",
    "field_metrics",
    "field_variance",
    "FieldSplit",
    "heldout_frequency_indices",
    "heldout_measurement",
    "heldout_scores",
    "HeldoutMeasurement",
    "HeldoutScores",
    "image_metrics",
    "kernel_power",
    "ncc",
    "normalise",
    "parameter_data_ratio",
    "psnr",
    "reconstruction_scores",
    "rmse",
    "scattered_field",
    "Scored",
    "scored",
    "SpatialPattern",
    "SpatialSampling",
    "SpectralSplit",
    "split_counts",
    "split_field",
    "ssim",
]
__getattr__, __dir__ = lazy_exports(__name__, __file__)
