"""Shared pytest configuration: make ``tests/scenes.py`` importable in any import mode, and
keep the bytecode of what the tests import, and compile kernels ahead on a cold cache."""

import contextlib
import logging
import os
import sys
import warnings

import pytest

sys.path.insert(0, os.path.dirname(__file__))

# Where PYTHONDONTWRITEBYTECODE is set no process writes bytecode: pytest would rewrite the
# asserts of every test module again each session (about 2 s), and every process a test
# starts (command line, batch and Dask workers, numba's compile-ahead helper) would compile
# rtmesh's 25,000 lines from source again (about 0.15 s each).  This process writes it, into
# the __pycache__ folders (ignored by git, already holding numba's caches), as rtmesh and
# the test modules are imported during collection, before any test starts a process; the
# others read it.  Python checks each file's time and size against its source, so an edited
# module never runs stale.
sys.dont_write_bytecode = False


# The session runs inside compile_ahead.helper(), as the rtmesh command runs a render: on a
# cold numba cache (CI installs from scratch) a helper process compiles each kernel group a
# render announces from its end while the render compiles it from its start, on the second
# core.  The path kernel, the largest compile by far (about 34 s of one core, one
# function), is announced at once, so the helper compiles it while the first tests run;
# the first path render waits for what remains (its lock file) and loads it from the disk
# cache.  With a warm cache no helper starts.  Every render computes what it computes
# outside the block: the helper only fills the disk cache.  Under pytest-xdist each worker
# process has its own block (and helper); the lock files keep two processes from compiling
# a grouped kernel twice.
_session = contextlib.ExitStack()


def pytest_configure(config):
    if getattr(config.option, "numprocesses", None) and not hasattr(config, "workerinput"):
        return  # pytest-xdist's controller: its workers run the tests
    from rtmesh.core import compile_ahead
    from rtmesh.rendering.caustics import PHOTON_KERNELS
    from rtmesh.rendering.path_signatures import PATH_KERNELS

    _session.enter_context(compile_ahead.helper())
    PATH_KERNELS.compile_ahead()
    PHOTON_KERNELS.compile_ahead()


def pytest_unconfigure(config):
    _session.close()


# The tests that render with the path integrator (its kernel group, ``PATH_KERNELS``) and,
# after them, those that trace photons (``PHOTON_KERNELS``), by module (under tests/) and
# test function ("*": every test of the module): they run last.  On a cold numba cache the
# compile helper spends the first minute of the session on the path kernel and the next
# half minute on the photon kernel; a test that renders with either earlier waits for it
# (its lock file) and leaves its core idle, and when both workers wait only the helper's
# core works.  In this order each worker has other tests to run meanwhile.  Only the order
# changes: a test missing here still passes, it may wait on a cold cache.  (A test's
# kernel groups: wrap ``rtmesh.core.compile_ahead.KernelGroup.prepare`` in a plugin that
# writes the group's name and the running test.)
_PATH_TESTS = {
    "batch/test_batch.py": ("test_editing_a_dependency_or_damaging_an_image_redoes_it",),
    "batch/test_batch_instances.py": ("test_the_worker_traces_the_placements_as_instances",),
    "batch/test_many_views.py": ("test_physical_assets_get_the_studio_turned_to_each_view",),
    "core/test_compile_ahead.py": ("test_a_path_render_of_one_ray_calls_the_path_kernel_with_the_declared_types",),
    "core/test_runtime.py": ("test_the_render_command_tunes_its_process",),
    "geometry/test_cutouts.py": ("test_path_sees_moving_cutouts_as_whitted_does",
                                 "test_path_shadows_through_moving_cutouts_as_whitted_does"),
    "io/test_passes.py": ("test_exr_holds_every_pass_under_its_layer_names_and_pngs_map_them",
                          "test_passes_are_bit_identical_across_threads_and_chunk_sizes"),
    "lights/test_projector.py": ("test_path_lights_the_floor_with_the_projected_texel_times_cos_over_d_squared",
                                 "test_path_shows_the_projected_image_where_whitted_does"),
    "loaders/test_compressed_gltf.py": ("test_a_compressed_glb_renders_the_plain_files_image",),
    "loaders/test_gltf_scene.py": ("test_bare_gltf_renders_from_its_first_camera_with_its_lights",),
    "loaders/test_importers.py": ("test_gltf_faces_with_indices_beyond_the_vertices_are_dropped_with_a_count",
                                  "test_hidden_nodes_are_one_warning_for_the_file_and_the_rest_renders"),
    "loaders/test_load_memory.py": ("test_ten_thousand_placements_of_a_large_mesh_render_within_a_small_limit",
                                    # its batch worker process renders a glTF asset
                                    "test_a_batch_worker_fails_an_asset_beyond_its_limit_at_the_load_stage"),
    "loaders/test_placements.py": ("test_an_instances_file_renders_as_the_copies_under_path",
                                   "test_objects_importing_one_file_share_it",
                                   "test_usd_instancers_and_instanceable_prims_place_one_mesh"),
    "loaders/test_real_assets.py": ("test_real_asset_renders_or_fails_with_one_line",),
    "loaders/test_usd_files.py": ("test_a_folder_of_usd_files_renders_in_batch",
                                  "test_a_usd_file_renders_on_the_command_line"),
    "materials/test_khr_layers.py": ("test_a_clear_coat_reflects_over_a_black_base",
                                     "test_anisotropy_follows_its_rotation_from_the_uv_tangents",
                                     "test_layered_materials_render_under_path_with_their_textures"),
    "rendering/test_cornell_box.py": ("test_path_integrator_has_the_mitsuba_references_means",),
    "rendering/test_light_samples.py": ("*",),
    "rendering/test_media.py": ("test_path_through_glass_in_water_matches_the_closed_form",
                                "test_roulette_inside_glass_adds_no_noise"),
    "rendering/test_path_integrator.py": ("*",),
    "rendering/test_whitted_kernel.py": ("*",),
    "sampling/test_zsobol.py": ("test_path_renders_do_not_depend_on_threads_or_chunks",),
    "scene/test_instancing.py": ("*",),
    "test_bad_inputs.py": ("test_bad_input[bad_pbr_extensions.gltf]", "test_bad_input[zero_scale.gltf]"),
}
_PHOTON_TESTS = {  # in this order: the two longest (10 and 6 s) apart, with short ones between
    "rendering/test_feature_combinations.py": ("*",),
    "rendering/test_light_samples.py": ("test_light_samples_do_not_depend_on_the_thread_count",
                                        "test_light_samples_lower_the_error_of_soft_shadows_at_equal_spp",
                                        "test_what_the_camera_sees_in_a_mirror_takes_the_light_samples"),
    "rendering/test_caustics.py": ("*",),
    "lights/test_projector.py": ("test_a_white_projector_throws_the_caustics_of_the_spot_light_it_equals",),
    "rendering/test_path_integrator.py": ("test_light_path_passes_sum_to_the_image",),
    "scene/test_instancing.py": ("test_annotations_of_placements_are_their_copies",
                                 "test_passes_come_out_of_the_instanced_scene",
                                 "test_the_denoiser_and_a_transparent_background_keep_instances"),
}


def _listed(table, module, item):
    names = table.get(module, ())
    return "*" in names or item.name in names or getattr(item, "originalname", item.name) in names


def pytest_collection_modifyitems(config, items):
    """Path kernel tests after the others, photon tests last, module by module in the order
    of _PHOTON_TESTS (see _PATH_TESTS); a stable sort, the same in every xdist worker."""
    tests = os.path.dirname(os.path.abspath(__file__))
    photon_modules = list(_PHOTON_TESTS)

    def rank(item):
        module = os.path.relpath(str(item.path), tests).replace(os.sep, "/")
        if _listed(_PHOTON_TESTS, module, item):
            return 2, photon_modules.index(module)
        return (1, 0) if _listed(_PATH_TESTS, module, item) else (0, 0)

    items.sort(key=rank)


@pytest.fixture
def cli(capsys, caplog):
    """Run the ``rtmesh`` command in this process, as ``python -m rtmesh.cli ARGS`` would:
    ``cli(*args)`` returns (exit status, stdout, stderr).

    For the tests of what a command says, not of the process: a process costs about 1 s
    of CPU to import rtmesh (the tests of the real entry point run one).  argparse's
    SystemExit gives its status.  What a process would print to stderr and pytest catches
    here is added to stderr, so a stray line still breaks a one-line check: the command's
    log records of WARNING and above (its ``logging.basicConfig`` handler, which pytest's
    own handlers pre-empt), and Python warnings a process shows (not the deprecation,
    import and resource warnings its default filters hide; a RuntimeWarning still fails
    the test, as the suite's filter says).
    """
    from rtmesh.cli import main

    hidden = (DeprecationWarning, PendingDeprecationWarning, ImportWarning, ResourceWarning)

    def run(*args):
        capsys.readouterr()
        caplog.clear()
        with caplog.at_level(logging.WARNING), warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            warnings.simplefilter("error", RuntimeWarning)
            try:
                code = main([str(a) for a in args])
            except SystemExit as exc:
                code = exc.code
        out, err = capsys.readouterr()
        err += "".join(f"rtmesh: warning: {r.getMessage()}\n" for r in caplog.records
                       if r.levelno >= logging.WARNING)
        err += "".join(f"{w.filename}:{w.lineno}: {w.category.__name__}: {w.message}\n" for w in caught
                       if not issubclass(w.category, hidden))
        return code, out, err

    return run


@pytest.fixture
def in_process_jobs():
    """Local batches of the test run their jobs in the test process, not in worker
    processes (tests/local_jobs.py): for tests that are not about the pool."""
    from local_jobs import jobs_in_this_process

    with jobs_in_this_process():
        yield
