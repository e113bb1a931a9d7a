"""Which pairs of views to match: all, neighbours in a sequence or on a ring, or a bag-of-words shortlist."""
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..core.validation import as_count, as_rng
from .descriptors import _as_descriptors, nearest_neighbours

# ---------------------------------------------------------------------------------------------
# Which pairs to match
# ---------------------------------------------------------------------------------------------

def select_pairs(n_views: int, strategy: str = "all", window: int | None = None) -> np.ndarray:
    """The pairs of views to match.

    ``'all'``: every pair (``V (V - 1) / 2``: fine for tens of views, quadratic beyond). ``'sequence'``:
    views at most ``window`` apart in the order given (a video, a walk around). ``'ring'``: the same on a
    closed loop (a turntable), so the last views also meet the first ones.

    Parameters
    ----------
    n_views : int
    strategy : {'all', 'sequence', 'ring'}
    window : int
        Required for 'sequence' and 'ring': an integer >= 1.

    Returns
    -------
    pairs : (P, 2) int ndarray
        Rows ``(i, j)`` with ``i < j``, sorted.

    Examples
    --------
    >>> select_pairs(4).tolist()
    [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]
    >>> select_pairs(5, "ring", window=1).tolist()
    [[0, 1], [0, 4], [1, 2], [2, 3], [3, 4]]
    """
    V = as_count(n_views, "n_views", 2)
    i, j = np.triu_indices(V, 1)
    if strategy == "all":
        keep = np.ones(i.size, bool)
    elif strategy in ("sequence", "ring"):
        if window is None:
            raise ValueError(f"strategy '{strategy}' needs a window >= 1; got None")
        window = as_count(window, "window")
        gap = j - i
        if strategy == "ring":
            gap = np.minimum(gap, V - gap)
        keep = gap <= window
    else:
        raise ValueError(f"strategy must be 'all', 'sequence' or 'ring'; got {strategy!r}")
    return np.column_stack([i[keep], j[keep]]).astype(np.int64)


def retrieval_pairs(descriptors: Sequence[ArrayLike], n_neighbours: int, *, rng: np.random.Generator,
                    vocabulary_size: int = 256, sample: int = 20000) -> tuple[np.ndarray, np.ndarray]:
    """A shortlist of pairs from a bag of visual words (Sivic & Zisserman, "Video Google", ICCV 2003).

    A vocabulary of ``vocabulary_size`` words is learnt by k-means on a sample of all descriptors; each image
    becomes a histogram of its words, weighted by tf-idf and normalised; each image is paired with the
    ``n_neighbours`` images whose histograms are most similar (cosine). Costs one k-means and one
    ``V × V`` product instead of ``V (V - 1) / 2`` pair matchings.

    Parameters
    ----------
    descriptors : sequence of V (N_v, D) arrays
    n_neighbours : int
        Per image, >= 1 (the shortlist holds at most ``V · n_neighbours`` pairs).
    rng : numpy.random.Generator
        For the sample and the k-means seeds.
    vocabulary_size : int
        >= 1.
    sample : int
        Descriptors drawn to learn the vocabulary, >= ``vocabulary_size``.

    Returns
    -------
    pairs : (P, 2) int ndarray
        ``i < j``, sorted.
    similarity : (V, V) ndarray
        Cosine similarity of the tf-idf histograms: 1 on the diagonal, except for an image whose words all
        appear in every image (their idf is 0, so its histogram is zero): its row and column are 0.
    """
    import scipy.cluster.vq

    as_rng(rng)
    n_neighbours = as_count(n_neighbours, "n_neighbours")
    vocabulary_size = as_count(vocabulary_size, "vocabulary_size")
    sample = as_count(sample, "sample")
    if sample < vocabulary_size:
        raise ValueError(f"sample must be >= vocabulary_size = {vocabulary_size} (k-means starts from sampled "
                         f"descriptors); got {sample}")
    D = [_as_descriptors(d, f"descriptors[{v}]") for v, d in enumerate(descriptors)]
    V = len(D)
    if V < 2:
        raise ValueError(f"need descriptors of at least 2 images; got {V}")
    every = np.concatenate(D)
    if len(every) < vocabulary_size:
        raise ValueError(f"{len(every)} descriptors in all, fewer than vocabulary_size = {vocabulary_size}")
    train = every[rng.choice(len(every), min(sample, len(every)), replace=False)]
    # random descriptors as the initial words ('++' seeding is better in theory but takes a minute here)
    codebook, _ = scipy.cluster.vq.kmeans2(train, vocabulary_size, iter=10, minit="points", seed=rng)
    H = np.zeros((V, vocabulary_size))
    for v, d in enumerate(D):
        if len(d):
            words = nearest_neighbours(d, codebook.astype(np.float32), k=1)[0][:, 0]
            H[v] = np.bincount(words, minlength=vocabulary_size)
    idf = np.log(V / np.maximum((H > 0).sum(0), 1))
    W = H / np.maximum(H.sum(1, keepdims=True), 1) * idf
    W /= np.maximum(np.linalg.norm(W, axis=1, keepdims=True), 1e-300)
    S = W @ W.T
    order = np.argsort(-(S - 2 * np.eye(V)), axis=1)[:, :n_neighbours]
    pairs = {(min(a, b), max(a, b)) for a in range(V) for b in order[a].tolist()}
    return np.array(sorted(pairs), np.int64).reshape(-1, 2), S
