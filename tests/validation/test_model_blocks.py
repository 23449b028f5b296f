"""A assembled from blocks of pairs on Dask workers is the machine's A, bit for bit."""

import numpy as np

from analytic.scenes.relay_wall import Scan, default_relay_wall_scene
from analytic.scenes.common import Sampling, default_scene
from analytic.operator.system import system_matrix
from validation.model_blocks import system_matrix_on_dask
from validation.sweep.driver import sweep_client


def _equal(first, second):
    return (first.shape == second.shape and np.array_equal(first.indptr, second.indptr)
            and np.array_equal(first.indices, second.indices) and np.array_equal(first.data, second.data))


def test_pair_blocks_on_one_and_two_workers_give_the_same_matrix():
    plane = default_scene().replace(pixels=12, reflectance=np.full((12, 12), 0.5))
    nlos = default_relay_wall_scene(pixels=6, scan=Scan(type="confocal", grid=(3, 3)),
                                    sampling=Sampling(bin_width_opl=0.05, start_opl=1.9, count=28))
    whole = [system_matrix(plane), system_matrix(nlos)]
    with sweep_client(workers=1) as client:
        one = [system_matrix_on_dask(plane, client, pairs_per_task=3),
               system_matrix_on_dask(nlos, client, pairs_per_task=2)]
    with sweep_client(workers=2) as client:
        two = [system_matrix_on_dask(plane, client, pairs_per_task=5),
               system_matrix_on_dask(nlos, client, pairs_per_task=4)]
    for reference, on_one, on_two in zip(whole, one, two):
        assert reference.nnz > 0
        assert _equal(reference, on_one) and _equal(reference, on_two)
