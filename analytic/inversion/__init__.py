"""Image recovery from the samples: y = A f solved for f with a regulariser and a λ rule.

The paper's Laplacian-Tikhonov reconstruction (:mod:`.tikhonov`, its λ
rules in :mod:`.rules`, the Laplacian in :mod:`.laplacian`), total
variation beyond the paper (:mod:`.tv`), the rule on photon counts
(:mod:`.poisson`), and the image metrics (:mod:`.metrics`). Each function takes (operator, data, regulariser, λ rule)
and returns a :class:`Reconstruction`. Names are loaded on first use
(``lazy_loader``, as in every package of this project).
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "tikhonov": ["reconstruct", "reconstruct_rules", "METHODS"],
    "tv": ["reconstruct_tv", "TV_RULES", "total_variation"],
    "result": ["Reconstruction", "RankDeficiencyWarning", "NoiseLimitWarning", "RegularizationWarning"],
    "rules": ["RULES", "DEFAULT_LAMBDA_COUNT", "lambda_grid"],
    "metrics": ["image_metrics", "structural_similarity", "flat_image_psnr"],
    "laplacian": ["neumann_laplacian", "laplacian_eigenvalues", "dct2", "idct2"],
    "bounds": ["crb", "Bounds", "information_bounds"],
    "poisson": ["reconstruct_counts", "poisson_map", "compare_to_map", "rate_estimate"],
})
