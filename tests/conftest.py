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
# core.  The path kernel's group (its stages, about 50-70 s of one core) and the photon
# tracer's are announced at once, so the helper compiles them while the first tests run;
# the first path render waits for what remains (its lock file) and loads it from the disk
# cache.  With a warm cache no helper starts.  Every render computes what it computes
# outside the block: the helper only fills the disk cache.  Under pytest-xdist each worker
# process has its own block (and helper), and only the first worker announces the two
# groups: the two helpers would otherwise share their kernels out by the lock files, and
# each compile again the rows the other had compiled (the photon tracer after the path
# stages in one process: about 6 s of CPU; in the other helper: about 20 s).
_session = contextlib.ExitStack()


def pytest_configure(config):
    if getattr(config.option, "numprocesses", None) and not hasattr(config, "workerinput"):
        return  # pytest-xdist's controller: its workers run the tests
    from rtmesh.core import compile_ahead
    from rtmesh.rendering.caustics import PHOTON_KERNELS
    from rtmesh.rendering.path_signatures import PATH_KERNELS

    _session.enter_context(compile_ahead.helper())
    if getattr(config, "workerinput", {}).get("workerid", "gw0") == "gw0":
        PATH_KERNELS.compile_ahead()
        PHOTON_KERNELS.compile_ahead()


def pytest_unconfigure(config):
    _session.close()


# The tests that render with the path integrator's kernel (``PATH_KERNELS``; Whitted scenes
# the fused direct stage does not take render with it too, in-process or in the batch
# worker processes a test starts) and, after them, those that trace photons
# (``PHOTON_KERNELS``), by module (under tests/) and test function ("*": every test of the
# module): they run last.  On a cold numba cache the compile helper spends the first one
# to two minutes of the session on the two groups; a test that renders with either earlier
# either waits for the kernel the helper is compiling (its lock file; the core idles) or
# compiles the group's first kernels itself, the rows they share with the helper's a
# second time.  In this order each worker has other tests to run meanwhile.  Only the order
# changes: a test missing here still passes, it may wait on a cold cache.  (A test's
# kernel groups: wrap ``rtmesh.core.compile_ahead.KernelGroup.prepare`` in a plugin that
# writes the group's name and the running test, in its batch worker processes too.)
_PATH_TESTS = {
    "batch/test_annotations.py": ("test_a_moving_objects_pose_is_where_the_shutter_opens",),
    "batch/test_asset_meta.py": ("*",),
    "batch/test_batch.py": ("test_a_killed_worker_keeps_the_images_it_finished_and_is_not_called_out_of_memory",
                            "test_a_lost_scheduler_ends_the_batch_with_its_own_exit_code_and_no_failures",
                            "test_corrupt_files_in_the_middle_of_a_batch_fail_alone",
                            "test_dask_cluster_with_a_worker_killed_mid_batch",
                            "test_dask_worker_with_a_private_output_folder_is_refused",
                            "test_editing_a_dependency_or_damaging_an_image_redoes_it",
                            "test_memory_guard_fails_an_asset_that_needs_too_much",
                            "test_resume_after_sigkill_writes_every_image_exactly_once",
                            "test_resume_right_after_killing_the_client_gives_each_image_one_writer",
                            "test_summary_to_a_closed_pipe_and_jsonl_progress",
                            "test_time_limit_stops_a_runaway_asset_and_the_batch_goes_on",
                            "test_warm_up_converts_a_tiny_asset_one_worker_per_host_first"),
    "batch/test_batch_cameras.py": ("*",),
    "batch/test_batch_instances.py": ("*",),
    "batch/test_datasets.py": ("*",),
    "batch/test_flow.py": ("*",),
    "batch/test_many_views.py": ("*",),
    "batch/test_view_labels.py": ("*",),
    "core/test_compile_ahead.py": ("test_a_path_render_of_one_ray_calls_the_path_kernel_with_the_declared_types",
                                   "test_renders_call_the_declared_kernels_with_the_declared_types"),
    "core/test_runtime.py": ("test_the_image_does_not_depend_on_the_tuning",
                             "test_the_render_command_tunes_its_process"),
    "geometry/test_cutouts.py": ("*",),
    "geometry/test_hard_geometry.py": ("*",),
    "geometry/test_motion.py": ("test_a_smooth_ball_spinning_about_its_centre_looks_still",
                                "test_area_light_shadows_see_moving_objects_at_the_rays_time",
                                "test_motion_blur_is_bit_identical_across_threads_and_chunks",
                                "test_motion_path_with_zero_motion_is_bit_identical_to_the_static_path",
                                "test_rotating_object_matches_the_average_of_static_renders",
                                "test_shadow_of_a_moving_object_is_blurred_like_the_time_average",
                                "test_sliding_floor_has_no_self_intersection",
                                "test_sliding_strip_coverage_matches_the_time_average"),
    "io/test_denoising.py": ("*",),
    "io/test_passes.py": ("test_albedo_is_the_diffuse_colour_of_the_material_hit",
                          "test_alpha_is_the_fraction_of_samples_that_hit",
                          "test_box_normals_are_exactly_the_normal_of_the_face_each_pixel_sees",
                          "test_depth_is_the_nearest_sample_at_a_silhouette_and_zero_where_nothing_is_hit",
                          "test_depth_of_a_wall_facing_the_camera_is_its_distance_in_every_pixel",
                          "test_exr_holds_every_pass_under_its_layer_names_and_pngs_map_them",
                          "test_motion_is_where_each_centre_hit_lands_when_the_shutter_closes",
                          "test_only_requested_passes_are_computed_and_stored",
                          "test_passes_are_bit_identical_across_threads_and_chunk_sizes",
                          "test_position_is_world_space_far_from_the_origin",
                          "test_uv_pass_interpolates_the_scenes_texture_coordinates"),
    "lights/test_area_lights.py": ("test_a_light_flush_with_a_ceiling_lights_the_room_and_is_seen",
                                   "test_a_point_on_an_emissive_triangle_does_not_sample_its_own_plane_by_zero_over_zero",
                                   "test_a_textured_emitter_is_seen_and_lights_with_its_texels",
                                   "test_area_light_stages_run_only_for_scenes_with_area_lights",
                                   "test_disk_light_on_its_axis_matches_the_closed_form",
                                   "test_emissive_mesh_emission_is_seen_from_both_sides_and_lights_both",
                                   "test_emissive_mesh_lights_like_the_equivalent_quad_light",
                                   "test_light_samples_flag_sets_the_shadow_rays_per_hit",
                                   "test_shipped_soft_shadow_scene_renders",
                                   "test_soft_shadow_image_is_identical_for_any_thread_count_and_chunk_size",
                                   "test_soft_shadow_render_has_umbra_penumbra_and_full_light",
                                   "test_stratified_ao_at_the_foot_of_a_wall_and_in_a_corner_is_exact",
                                   "test_tiny_quad_light_renders_like_the_equivalent_point_light_highlight_included",
                                   "test_visible_area_light_is_seen_from_its_front_only_and_in_mirrors"),
    "lights/test_environment_lighting.py": ("*",),
    "lights/test_projector.py": ("*",),
    "loaders/test_compressed_gltf.py": ("*",),
    "loaders/test_gltf_scene.py": ("*",),
    "loaders/test_importers.py": ("test_gltf_faces_with_indices_beyond_the_vertices_are_dropped_with_a_count",
                                  "test_hidden_nodes_are_one_warning_for_the_file_and_the_rest_renders"),
    "loaders/test_load_memory.py": ("test_ten_thousand_placements_of_a_large_mesh_render_within_a_small_limit",
                                    # its batch worker process renders a glTF asset
                                    "test_a_batch_worker_fails_an_asset_beyond_its_limit_at_the_load_stage"),
    "loaders/test_hostile_meshes.py": ("test_nan_texture_coordinates_in_a_ply_are_one_warning_and_no_numpy_warning",),
    "loaders/test_placements.py": ("*",),
    "loaders/test_real_assets.py": ("*",),
    "loaders/test_texture_transform.py": ("*",),
    "loaders/test_usd_files.py": ("test_a_folder_of_usd_files_renders_in_batch",
                                  "test_a_usd_stage_renders_as_the_same_scene_file"),
    "materials/test_glossy.py": ("*",),
    "materials/test_khr_layers.py": ("*",),
    "rendering/test_adaptive.py": ("*",),
    "rendering/test_caustics.py": ("*",),
    "rendering/test_cornell_box.py": ("*",),
    "rendering/test_depth_of_field.py": ("*",),
    "rendering/test_determinism.py": ("*",),
    "rendering/test_direct_stage.py": ("*",),
    "rendering/test_exact_sphere_reference.py": ("*",),
    "rendering/test_integrator_stages.py": ("*",),
    "rendering/test_light_sampler.py": ("*",),
    "rendering/test_light_samples.py": ("*",),
    "rendering/test_media.py": ("*",),
    "rendering/test_memory.py": ("*",),
    "rendering/test_path_camera.py": ("*",),
    "rendering/test_path_integrator.py": ("*",),
    "rendering/test_physical_shading.py": ("*",),
    "rendering/test_stability.py": ("*",),
    "rendering/test_whitted_kernel.py": ("*",),
    "sampling/test_zsobol.py": ("test_adaptive_rounds_continue_each_pixel_and_estimate_the_error",
                                "test_path_renders_do_not_depend_on_threads_or_chunks",
                                "test_whitted_renders_do_not_depend_on_threads_or_chunks"),
    "scene/test_background.py": ("*",),
    "scene/test_camera_json.py": ("*",),
    "scene/test_instancing.py": ("*",),
    "shading/test_shading.py": ("*",),
    "test_bad_inputs.py": ("test_bad_input[bad_pbr_extensions.gltf]",
                           "test_bad_input[zero_scale.gltf]",
                           "test_mutated_mesh_files_render_or_fail_as_user_errors",
                           "test_scene_files_with_extreme_numbers_render_or_fail_as_user_errors"),
    "test_cli.py": ("test_bundled_showcase_scene_renders",
                    "test_render_writes_exr_and_png_that_read_back"),
}
_PHOTON_TESTS = {  # in this order: the two longest (10 and 6 s) apart, with short ones between
    "rendering/test_feature_combinations.py": ("*",),
    "rendering/test_light_samples.py": ("test_light_samples_do_not_depend_on_the_thread_count",
                                        "test_light_samples_lower_the_error_of_soft_shadows_at_equal_spp",
                                        "test_what_the_camera_sees_in_a_mirror_takes_the_light_samples"),
    "rendering/test_caustics.py": ("*",),
    "lights/test_projector.py": ("test_a_white_projector_throws_the_caustics_of_the_spot_light_it_equals",),
    "rendering/test_path_integrator.py": ("test_light_path_passes_sum_to_the_image",),
    "rendering/test_path_camera.py": ("test_the_kernels_camera_rays_are_the_cameras",),
    "loaders/test_placements.py": ("test_placed_glass_stays_placed_within_the_memory_limit",),
    "loaders/test_usd_files.py": ("test_a_usd_file_renders_on_the_command_line",),
    "scene/test_instancing.py": ("test_annotations_of_placements_are_their_copies",
                                 "test_cutout_prototypes_stay_placed_and_render_as_their_copies",
                                 "test_glass_prototypes_stay_placed_and_refract_as_their_copies",
                                 "test_normal_maps_bend_placed_meshes_as_their_copies",
                                 "test_passes_come_out_of_the_instanced_scene",
                                 "test_photon_passes_trace_placed_mirrors_as_their_copies",
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
