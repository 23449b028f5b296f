"""Image recovery from the samples: y = A f solved for f with a regulariser and a λ rule.

The paper's Laplacian-Tikhonov reconstruction (:mod:`.tikhonov`, its λ
rules in :mod:`.rules`, the Laplacian in :mod:`.laplacian`), total
variation beyond the paper (:mod:`.tv`), and the image metrics
(:mod:`.metrics`). Each function takes (operator, data, regulariser, λ rule)
and returns a :class:`Reconstruction`.
"""

from .laplacian import dct2, idct2, laplacian_eigenvalues, neumann_laplacian
from .metrics import flat_image_psnr, image_metrics, structural_similarity
from .result import RankDeficiencyWarning, Reconstruction, RegularizationWarning
from .rules import DEFAULT_LAMBDA_COUNT, RULES, lambda_grid
from .tikhonov import METHODS, reconstruct, reconstruct_rules
from .tv import TV_RULES, reconstruct_tv, total_variation

__all__ = ["reconstruct", "reconstruct_rules", "reconstruct_tv", "Reconstruction", "RankDeficiencyWarning",
           "RegularizationWarning", "RULES", "TV_RULES", "METHODS", "DEFAULT_LAMBDA_COUNT", "lambda_grid",
           "image_metrics", "structural_similarity", "flat_image_psnr", "total_variation",
           "neumann_laplacian", "laplacian_eigenvalues", "dct2", "idct2"]
