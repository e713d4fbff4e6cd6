"""Shared fixtures: the FMUs are built once per test session (only if stale).

At the end of a session the summary lists what the session left in the temporary
directory (pytest's own pytest-of-USER folder aside): a run should leave nothing.
On a machine where other processes share the folder, their new entries appear too.
"""
import importlib.util
import os
import sys
import tempfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


EVERY_TEST = "every test"
#: the tests left out of the fast loop (``-m "not slow"``, tests/README.md): per test file, its slow test
#: functions (every parametrisation), or EVERY_TEST. Slow: a co-simulation of seconds, another process or host,
#: a build of its own. tests/test_fast_loop.py holds every module to a fast test and every name here to a test.
SLOW = {
    "test_wheel_contents.py": EVERY_TEST,
    "test_aarch64_linux.py": EVERY_TEST,
    "test_adaptive_fuzzy_controller_fmu.py": ("test_bad_parameter_fails_initialisation_naming_it",
        "test_fmpy_command_line_matches_the_pure_math", "test_fmpy_validate_finds_no_problem",),
    "test_afc_math.py": ("test_projection_keeps_theta_below_bound_under_adversarial_tau",),
    "test_afc_math_c.py": ("test_p_solves_the_lyapunov_equation_as_scipy_does",
        "test_the_native_controller_fmu_is_the_python_one_at_any_order",),
    "test_archives.py": ("test_fmpys_ssp_path_leaves_nothing_when_a_run_fails",
        "test_run_ssp_refuses_a_bomb_fmu_inside_the_package_before_fmpy_unpacks_it",),
    "test_atomic_outputs.py": ("test_export_ssp_out_on_a_full_disk_keeps_the_previous_package",
        "test_run_out_on_a_full_disk_keeps_the_previous_csv_and_names_it",
        "test_the_reports_on_a_full_disk_keep_the_previous_ones",),
    "test_architecture.py": ("test_the_graph_sees_the_imports_it_must_see",
        "test_the_project_keeps_its_import_architecture",),
    "test_bench.py": ("test_bench_json_reports_every_figure_and_times_the_right_runs",
        "test_the_main_job_is_timed_as_a_user_runs_it",
        "test_the_native_section_times_ours_the_c_host_and_the_floor_at_each_horizon",),
    "test_c_baselines.py": ("test_the_c_host_and_the_floor_reproduce_the_masters_record_over_the_whole_horizon",
        "test_callgrind_counts_the_floors_instructions_per_step",),
    "test_build_native.py": ("test_the_controllers_signals_declare_the_plants_quantities_in_both_editions_and_fmi_versions",
        "test_every_binary_exports_the_whole_fmi_api_and_nothing_else",
        "test_invalid_parameters_and_inputs_get_the_python_editions_messages",
        "test_libcosim_runs_the_native_fmus_from_the_exported_ssp_as_the_python_ones",
        "test_the_editions_agree_on_every_table_case", "test_the_fmi3_controller_matches_the_fmi2_one",
        "test_the_harness_edition_option_selects_the_fmus",),
    "test_build_native_windows.py": EVERY_TEST,
    "test_build_native_windows_me.py": EVERY_TEST,
    "test_c_host.py": ("test_a_c_host_runs_the_controller_fmu_like_fmpy",),
    "test_cases.py": ("test_lines_are_rate_limited_and_a_heartbeat_says_a_long_wait_is_not_a_hang",),
    "test_ci_recipes.py": ("test_both_files_validate_against_their_services_schemas",
        "test_the_github_actions_workflow_runs_its_commands",
        "test_the_gitlab_ci_job_fails_when_the_scenario_changed_and_runs_both_editions",
        "test_the_gitlab_ci_job_runs_its_script",),
    "test_cli.py": ("test_a_misspelt_option_or_choice_gets_its_close_match",
        "test_es1_es2_are_marked_n_a_on_a_horizon_shorter_than_the_reference_period",
        "test_every_bad_argument_of_every_subcommand_is_one_line_and_exit_2",
        "test_every_scenario_key_misspelt_and_every_value_of_the_wrong_type_is_one_line_and_exit_2",
        "test_sweep_writes_docs_only_with_apply_and_says_what_it_changed",),
    "test_cluster.py": ("test_every_worker_lost_the_files_go_again_to_the_next_and_none_at_all_is_said",
        "test_a_short_tune_on_the_cluster_finishes_as_the_local_pool_does",
        "test_a_sweep_on_the_cluster_gives_the_local_pools_rows_and_ships_the_fmus_once",
        "test_a_worker_killed_mid_sweep_loses_nothing_and_counts_nothing_twice",
        "test_the_scheduler_gone_mid_sweep_is_one_line_and_the_sweep_resumes",
        "test_a_monte_carlo_study_on_the_cluster_gives_the_local_pools_rows",
        "test_a_worker_killed_mid_study_loses_no_run_and_counts_none_twice",
        "test_the_recipe_of_a_study_of_short_runs_survives_a_killed_worker_and_an_interrupt",),
    "test_compat.py": ("test_a_reference_that_fmpy_does_not_reproduce_is_marked_failed",
        "test_every_fmu_of_both_editions_and_every_declared_interface_is_published",
        "test_every_reference_comes_back_from_fmpy_simulate_on_its_inputs",
        "test_model_exchange_entries_agree_with_the_reference_where_the_model_is_smooth",
        "test_the_directory_validates_clean_with_fmpys_cross_check_validator",
        "test_the_files_keep_the_layouts_limits_and_name_only_the_fmus_variables",
        "test_the_validation_sees_a_broken_file",),
    "test_cures.py": ("test_with_the_cures_off_every_shipped_scenario_records_what_it_did_before_them",),
    "test_dc_motor_arm.py": ("test_master_run_matches_the_closed_loop_written_from_the_equations",),
    "test_continuous_reference.py": EVERY_TEST,
    "test_default_tolerance.py": ("test_plant_in_fmpys_model_exchange_with_its_declared_tolerance_is_within_a_thousandth",
        "test_controller_in_fmpys_model_exchange_with_its_declared_tolerance_is_within_a_thousandth",),
    "test_determinism.py": EVERY_TEST,
    "test_divergence.py": EVERY_TEST,
    "test_docs_data.py": ("test_table_rows_in_the_docs_are_those_the_tables_command_prints",
        "test_the_cost_of_the_claims_ladders_is_the_step_count_of_the_tables_run",
        "test_the_deciding_numbers_of_the_claims_are_those_of_the_report",
        "test_the_model_exchange_verdicts_quoted_are_those_tables_me_decides",
        "test_the_readmes_verdicts_are_what_the_claims_code_decides",
        "test_the_runs_the_docs_count_are_those_the_tables_command_makes",),
    "test_error_bars.py": EVERY_TEST,
    "test_engines.py": ("test_a_host_that_is_not_python_needs_libpython_preloaded",
        "test_a_model_exchange_package_declares_omsimulators_cvode_for_every_component",
        "test_ecos_and_our_jacobi_master_agree_inside_the_tube_and_to_rounding",
        "test_ecos_applies_the_parameter_set_only_when_init_names_it",
        "test_ecos_propagates_initial_values_so_start_inputs_are_not_needed",
        "test_ecos_records_outputs_after_setting_the_next_inputs", "test_export_and_run_ssp_commands",
        "test_exported_package_layout_parameters_and_schema",
        "test_fmpy_simulate_ssp_does_not_apply_the_package_parameter_bindings_by_itself",
        "test_fmpy_ssp_simulator_agrees_with_our_jacobi_master_after_its_start_transient",
        "test_fmpy_stamps_each_row_with_the_time_before_the_step_that_produced_it",
        "test_fmpy_starts_connectors_at_zero_and_the_controller_relatches_e0",
        "test_our_default_feedthrough_master_agrees_with_both_engines_at_a_small_step", "test_scores_side_by_side",
        "test_the_step_is_in_every_engines_annotation",),
    "test_exit_safety.py": EVERY_TEST,
    "test_executors.py": ("test_a_local_pool_does_every_task_once_under_its_key",
        "test_a_task_that_kills_its_worker_is_lost_alone_and_every_other_is_done_once",
        "test_the_task_of_a_lost_worker_runs_again", "test_worker_state_is_made_once_per_worker_and_kept_across_tasks",
        "test_a_batch_whose_worker_dies_is_split_and_only_its_culprit_is_lost",),
    "test_extras.py": ("test_a_command_that_needs_a_missing_extra_says_which_in_one_line",
        "test_the_host_matrix_skips_a_host_whose_extra_is_missing_and_says_so",
        "test_the_main_job_runs_on_the_core_install_alone_in_the_compiled_loop",
        "test_without_the_compiler_the_master_falls_back_to_its_python_loop",),
    "test_fast_loop.py": ("test_every_suite_run_prints_the_fast_loops_slowest_tests_before_the_summary_line",),
    "test_fmi_rules.py": ("test_a_fixed_parameter_is_accepted_after_instantiation_and_in_initialisation_mode",
        "test_a_fixed_parameter_written_after_initialisation_is_refused_and_keeps_its_value",),
    "test_fmu_bad_inputs.py": ("test_every_invalid_parameter_fails_initialisation_naming_it_its_value_and_range",
        "test_huge_finite_inputs_give_finite_outputs_or_an_error_never_nan",
        "test_non_finite_input_at_any_moment_is_an_error_never_a_non_finite_output",),
    "test_fmucheck.py": EVERY_TEST,
    "test_hardware_fmus.py": ("test_both_editions_draw_the_pure_functions_noise_bit_for_bit",
        "test_the_samples_depend_neither_on_the_hosts_step_nor_on_the_host",
        "test_a_sample_inside_a_step_comes_from_the_input_held_over_it_and_the_delay_line_starts_full",
        "test_the_actuator_saturates_delays_and_slews_as_the_exact_solution",
        "test_without_initial_values_both_start_from_the_inputs_of_the_first_step",
        "test_a_host_that_reads_before_it_sets_gets_one_warning_naming_the_time",
        "test_model_exchange_takes_the_samples_at_announced_time_events",
        "test_fmpy_in_model_exchange_gets_the_co_simulation_samples",
        "test_the_actuator_in_model_exchange_integrates_the_slew_law",
        "test_a_clockless_quantiser_is_refused_in_model_exchange_and_kept_in_co_simulation",),
    "test_hardware_scenario.py": ("test_neutral_hardware_gives_todays_records_bit_for_bit",
        "test_a_jacobi_host_gets_the_hardwares_warning_and_a_feedthrough_master_none",),
    "test_hardware_study.py": ("test_the_committed_csv_is_what_the_command_computes",
        "test_a_short_run_of_the_command_writes_its_csv_and_section",
        "test_the_committed_cures_csv_is_what_the_command_computes",
        "test_a_short_run_of_the_cures_writes_its_csv_and_section",),
    "test_host_robustness.py": ("test_chatter_in_jacobi_warns_once", "test_no_warning_in_our_masters_converged_runs",
        "test_pinned_e0_de0_set_the_modified_error", "test_pinned_initial_error_is_used_without_warning",
        "test_plain_gauss_seidel_in_every_order_gets_the_converged_result",
        "test_plain_jacobi_manipulator_gets_the_converged_result",
        "test_plain_jacobi_without_propagation_gets_the_converged_result",),
    "test_independent_loop.py": ("test_the_manipulator_cases_reach_the_projection_bound",
        "test_the_master_runs_the_papers_closed_loop",),
    "test_life_cycle.py": ("test_200_life_cycles_in_one_process_neither_crash_nor_leak_classes",
        "test_closed_loop_state_restores_and_serialises_bit_for_bit",
        "test_two_loops_in_one_master_equal_each_loop_alone",),
    "test_loop_interface.py": ("test_a_changed_header_makes_another_library",
        "test_a_header_out_of_step_with_python_is_found", "test_the_python_layouts_and_codes_are_the_headers",),
    "test_master.py": ("test_console_script_and_module_entry_point_run",
        "test_cosimulation_matches_the_oracle",
        "test_csv_is_in_cross_check_style_and_thinned_on_request",
        "test_default_has_no_delay_and_jacobi_delays_each_connection_one_step",
        "test_divergence_stops_with_message_and_partial_result",
        "test_fmu_fault_stops_the_run_naming_instance_function_time_and_log",
        "test_jacobi_matches_the_delayed_oracle", "test_run_json_prints_exactly_one_object_with_the_keys",),
    "test_master_loop.py": ("test_a_failing_run_fails_alike_with_either_loop",
        "test_an_fmi3_failure_names_the_fmi3_function", "test_fmi3_fmus_give_bit_identical_runs_with_either_loop",
        "test_native_fmus_give_bit_identical_runs_with_either_loop",
        "test_progress_is_reported_at_the_same_rows_with_either_loop",
        "test_pythonfmu_fmus_give_bit_identical_runs_with_either_loop",),
    "test_ls_ref.py": ("test_stored_experiments_are_compats",
        "test_native_fmu_reproduces_its_embedded_reference",
        "test_python_fmu_reproduces_its_embedded_reference",),
    "test_matrix.py": ("test_chattering_rows_carry_the_step_warning_and_others_do_not",
        "test_every_host_at_its_validated_step_is_within_1_percent_without_false_warning",
        "test_markdown_lists_every_row_and_says_where_warnings_come_from",
        "test_the_matrix_compares_hosts_that_agree_with_each_other",
        "test_the_native_edition_gives_every_host_the_same_rows_and_warnings",),
    "test_me_accuracy.py": ("test_the_page_says_what_it_measured",
        "test_the_stuck_link_chatters_in_co_simulation_by_the_plant_step_against_the_step",
        "test_the_tolerance_ladder_converges_to_the_co_simulation_limit",),
    "test_me_fmpy_agreement.py": EVERY_TEST,
    "test_me_master.py": ("test_a_value_beyond_its_bound_stops_both_loops_alike",
        "test_agrees_with_the_co_simulation_extrapolated_to_a_zero_step",
        "test_an_integration_cvode_cannot_carry_out_stops_with_its_rows_and_reason",
        "test_fmi3_gives_the_fmi2_trajectory", "test_python_and_compiled_loops_are_bit_identical",
        "test_run_reports_the_integrators_work", "test_the_model_exchange_master_runs_the_masters_life_cycle",
        "test_the_stuck_link_rests_at_exactly_zero_and_breaks_away",),
    "test_memory_cycles.py": ("test_our_code_keeps_next_to_nothing_per_cycle",
                              "test_life_cycles_keep_no_more_than_pythonfmus_residual",
                              "test_the_performance_page_quotes_the_figures_measured"),
    "test_model_exchange.py": ("test_every_numerical_initial_dependency_is_declared",
        "test_fmpy_simulates_the_controller_as_solve_ivp_integrates_the_adaptive_law",
        "test_fmpy_simulates_the_manipulator_through_its_friction_events_as_the_python_model",
        "test_fmpy_simulates_the_motor_arm_as_solve_ivp_integrates_the_python_model",
        "test_fmpy_simulates_the_pendulum_as_solve_ivp_integrates_the_python_model",
        "test_fmpy_simulates_the_reference_alone", "test_fmpy_validate_is_clean",
        "test_fmu_state_get_set_and_serialize_round_trip_in_model_exchange",
        "test_the_arm_sticks_until_the_torque_overcomes_coulomb_friction_and_breaks_away_on_time",
        "test_the_compliance_checker_in_model_exchange_mode_is_clean",
        "test_the_initial_error_is_latched_from_the_inputs_the_host_set_for_the_initial_state",),
    "test_mutation.py": ("test_a_test_selection_that_does_not_run_is_an_error_not_a_kill",
        "test_every_mutation_pattern_matches_its_function_once",
        "test_the_command_kills_a_mutant_and_reports_a_survivor",),
    "test_no_silent_changes.py": ("test_a_build_writes_a_temporary_file_beside_the_fmu_then_replaces_it",
        "test_a_failed_build_keeps_the_previous_fmu_and_leaves_no_temporary_file",
        "test_two_builds_at_once_leave_one_whole_fmu",),
    "test_omsimulator.py": ("test_fmi3_co_simulation_runs_and_its_strongly_coupled_mode_refuses_it",
        "test_its_c_api_takes_the_step_from_the_package_and_matches_our_master",
        "test_its_matrix_rows_are_within_1_percent_without_warnings", "test_its_python_api_reads_no_step_annotation",
        "test_nothing_is_printed_after_a_process_that_ran_it_ends",
        "test_its_strongly_coupled_mode_is_first_order_in_its_maximum_step",),
    "test_plants.py": ("test_bad_parameter_fails_with_a_message_naming_it_and_its_range",
        "test_friction_opposes_motion_and_payload_follows_mr0_plus_mr1_sin_t",
        "test_manipulator_open_loop_matches_solve_ivp", "test_pendulum_open_loop_matches_solve_ivp",),
    "test_readme_commands.py": ("test_readme_block_runs_as_written",),
    "test_regression.py": ("test_all_twelve_cases_stay_inside_their_reference_tubes",
        "test_gamma_290_instead_of_300_fails_and_the_unchanged_case_passes",
        "test_model_exchange_holds_to_references_of_its_own",
        "test_scaled_result_fails_and_changed_step_is_reported", "test_the_references_hold_for_the_native_edition",),
    "test_regression_report.py": ("test_report_md_shows_html_in_names_as_text_and_the_html_report_escapes_it",
        "test_junit_with_update_and_a_file_as_references_are_usage_errors",
        "test_the_first_update_creates_the_references_with_the_scenarios_hash",
        "test_a_changed_controller_parameter_fails_and_the_junit_failure_names_the_signal",
        "test_a_mistake_in_the_metadata_tolerances_is_one_line_exit_2", "test_a_plain_run_passes_and_writes_junit",
        "test_a_run_more_than_twice_as_slow_as_its_reference_is_flagged",
        "test_an_edited_scenario_file_is_detected_by_its_hash_and_the_change_is_named",
        "test_an_update_keeps_the_tolerances_of_the_metadata",
        "test_headless_chromium_renders_the_report_with_every_plot",
        "test_per_signal_tolerances_in_the_reference_metadata_decide_each_signal",
        "test_the_html_report_shows_failing_signals_first_with_their_plots_and_every_link_resolves",
        "test_the_link_check_sees_a_missing_image",),
    "test_scenario_mistakes.py": ("test_a_broken_system_structure_is_one_line_naming_the_package",),
    "test_source_fmus.py": ("test_source_fmus_validate",
        "test_fmi2_sources_rebuild_to_the_same_results",
        "test_fmi3_build_description_rebuilds_to_the_same_results",),
    "test_step_study.py": ("test_apply_needs_the_full_study",
        "test_export_ssp_carries_the_jacobi_validated_step_unless_given",
        "test_quick_study_writes_only_into_its_output_folder", "test_run_warns_beyond_the_validated_step",
        "test_runs_are_scored_on_the_true_tracking_error",),
    "test_robustness.py": ("test_the_summary_does_not_depend_on_the_order_the_rows_finished_in",
        "test_a_distribution_that_can_draw_an_invalid_value_is_refused_before_any_run",
        "test_kept_instances_reset_between_samples_give_the_scores_of_a_fresh_run",
        "test_every_controller_runs_on_the_same_draws_the_plan_gives",
        "test_the_summary_is_recomputed_from_the_streamed_rows", "test_the_paired_differences_pair_each_sample_with_itself",
        "test_the_influence_ranking_is_salibs_rbd_fast_on_the_completed_runs",
        "test_the_figure_and_the_summary_file_are_written",
        "test_an_interrupted_study_resumes_with_only_the_missing_runs_and_the_same_rows",
        "test_a_rerun_with_other_settings_is_refused_in_one_line", "test_the_command_prints_the_summary_and_resumes",
        "test_on_a_rig_the_noise_seed_is_drawn_per_sample_and_shared_by_the_controllers"),
    "test_sweep.py": ("test_a_killed_sweep_resumes_without_recomputing_finished_points",
        "test_a_lost_worker_loses_points_not_the_sweep_and_resume_runs_them",
        "test_an_interrupted_sweep_stops_cleanly_and_resumes",
        "test_dask_cluster_gives_the_same_rows_as_the_local_pool",
        "test_failed_points_are_recorded_and_the_sweep_goes_on",
        "test_local_pool_sweep_records_every_point_with_scores_or_a_reason",
        "test_unreachable_scheduler_is_a_clear_error",),
    "test_tables.py": ("test_the_native_ladders_give_the_pythonfmu_editions_scores",
        "test_figures_define_the_controllers_and_draw_the_settling_band",
        "test_tables_in_model_exchange_decide_the_claims_on_tolerance_ladders",
        "test_tables_writes_tables_report_and_figures",),
    "test_temp_cleanup.py": ("test_a_run_killed_with_sigkill_leaves_folders_the_next_run_removes",
        "test_an_ecos_run_leaves_nothing", "test_tables_stopped_while_its_workers_run_leaves_nothing",
        "test_fmus_extracted_once_per_process_are_shared_renewed_and_removed",
        "test_the_driven_helper_removes_its_extraction",),
    "test_termination.py": ("test_tables_under_a_pipe_on_a_loaded_cpu_says_how_far_within_10_s_and_sigterm_ends_it",
        "test_a_signal_ends_the_pools_workers_and_what_they_started",
        "test_sigkill_of_the_command_leaves_no_pool_worker_behind",),
    "test_tune.py": ("test_a_process_killed_right_after_claiming_its_trial_leaves_a_trial_that_goes_stale",
        "test_a_database_another_process_is_creating_is_opened_once_it_is_there",
        "test_a_best_that_moves_at_half_the_step_is_pruned_not_reported",
        "test_a_database_server_that_cannot_be_used_is_one_line_exit_2_before_any_trial",
        "test_a_full_disk_mid_study_is_one_line_naming_the_database_and_keeps_the_trials",
        "test_a_run_killed_mid_trial_is_resumed_by_another_through_its_heartbeat",
        "test_another_seed_is_another_study_and_a_shared_study_says_whose_seed_it_samples",
        "test_the_password_reaches_no_terminal_log_or_file",
        "test_a_constraint_keeps_a_candidate_that_misses_it_from_being_best",
        "test_a_killed_run_resumes_with_every_finished_trial_kept",
        "test_a_study_writes_a_scenario_that_run_and_regress_take_and_run_reproduces_its_score_exactly",
        "test_bad_input_is_one_line_exit_2_and_leaves_the_database_untouched",
        "test_diverging_and_chattering_candidates_are_pruned_with_the_reason",
        "test_robust_scores_the_worst_case_over_the_grid",
        "test_the_report_says_plainly_when_no_trial_beat_the_start", "test_the_same_seed_gives_the_same_trials",
        "test_trials_of_dead_processes_are_failed_and_retried_those_of_live_ones_kept",
        "test_two_processes_drive_one_study_to_exactly_its_budget",),
    "test_unsafe_paths.py": EVERY_TEST,
    "test_units.py": ("test_table_figures_label_every_panel_with_its_unit",),
    "test_work_precision.py": ("test_a_short_run_measures_every_point_and_draws_the_figure",),
}
#: the markers (pyproject.toml sets --strict-markers: a misspelt marker is an error)
MARKERS = {"slow": "left out of the fast loop, -m 'not slow' (conftest.SLOW lists them; tests/README.md)"}


def pytest_configure(config):
    for name, meaning in MARKERS.items():
        config.addinivalue_line("markers", f"{name}: {meaning}")


def is_slow(file_name: str, function_name: str) -> bool:
    listed = SLOW.get(file_name, ())
    return listed == EVERY_TEST or function_name in listed


def pytest_collection_modifyitems(items):
    for item in items:
        function = getattr(item, "originalname", None) or item.name.split("[")[0]
        if is_slow(item.path.name, function):
            item.add_marker(pytest.mark.slow)


@pytest.fixture(scope="session")
def fmu_paths():
    from harness.fmu_build import builder as build_fmu

    return build_fmu.ensure_built()


#: set by .ci/run: a server the tests start (PostgreSQL, Dask) that cannot be had fails its tests instead of
#: skipping them, so that CI runs them or says why not
REQUIRE_SERVERS = os.environ.get("AFC_REQUIRE_SERVERS") == "1"


def _unavailable(reason: str):
    """Skip, or fail where the servers are required (AFC_REQUIRE_SERVERS=1)."""
    if REQUIRE_SERVERS:
        pytest.fail(f"{reason}; AFC_REQUIRE_SERVERS=1 (.ci/run) requires it", pytrace=False)
    pytest.skip(reason)


@pytest.fixture(scope="session")
def postgres():
    """A throwaway PostgreSQL server on 127.0.0.1 with a password, for the session (tests/cluster_helpers.py);
    skipped where PostgreSQL or its driver is missing, unless AFC_REQUIRE_SERVERS=1 (.ci/run installs
    Debian's package, the test extra psycopg, and requires them)."""
    from tests.cluster_helpers import PostgresServer, postgres_bin

    bin_dir = postgres_bin()
    if bin_dir is None:
        _unavailable("PostgreSQL is not installed (apt-get install postgresql; .ci/run installs it)")
    if importlib.util.find_spec("psycopg") is None:
        _unavailable("psycopg, the PostgreSQL driver of the postgres extra, is not installed")
    with PostgresServer(bin_dir) as server:
        yield server


@pytest.fixture
def dask_cluster(tmp_path):
    """``dask scheduler`` and two ``dask worker`` processes on 127.0.0.1, one thread each, started with the
    commands docs/studies.md prints (tests/cluster_helpers.py) and stopped after the test."""
    if importlib.util.find_spec("distributed") is None:
        _unavailable("dask.distributed, of the cluster extra, is not installed")
    from tests.cluster_helpers import DaskCluster

    with DaskCluster(2, tmp_path / "dask") as cluster:
        yield cluster


@pytest.fixture(scope="session")
def lag_plant_fmu(tmp_path_factory):
    """A user's plant FMU that the project does not ship (tests/data/first_order_lag_fmu.py), built once."""
    from harness.fmu_build import builder as build_fmu

    return build_fmu.build_script(ROOT / "tests" / "data" / "first_order_lag_fmu.py",
                                  tmp_path_factory.mktemp("lag_plant") / "FirstOrderLag.fmu", [])


@pytest.fixture(scope="module")
def unzipped(fmu_paths, tmp_path_factory):
    """{model identifier: extracted FMU folder}, extracted once per test module."""
    from fmpy import extract

    from tests.fmu_variables import FMU_IDS

    return {fmu_id: extract(str(fmu_paths[fmu_id]), str(tmp_path_factory.mktemp(fmu_id)))
            for fmu_id in FMU_IDS}


_TEMP_BEFORE = set()


def pytest_sessionstart(session):
    _TEMP_BEFORE.update(os.listdir(tempfile.gettempdir()))
    if hasattr(session.config, "workerinput"):  # a pytest-xdist worker: the controller said it all
        return
    if session.config.getoption("numprocesses", None):
        _build_before_the_workers_start(_say(session.config))
    else:
        _announce_stale_fmus(_say(session.config))


def _say(config):
    """One line on the terminal now, before the first test (pytest captures print)."""
    reporter = config.pluginmanager.get_plugin("terminalreporter")
    return reporter.write_line if reporter is not None else (lambda text: print(text, file=sys.stderr, flush=True))


def _stale() -> tuple:
    """(stale pythonfmu FMUs, stale native models or None without zig's compiler)."""
    from harness.fmu_build import builder as build_fmu
    from harness.fmu_build import native as build_native

    python = [fmu.model_identifier for fmu in build_fmu.FMUS if build_fmu.is_stale(fmu)]
    native = build_native.stale_models() if build_native.compiler_available() else None
    return python, native


def _announce_stale_fmus(say):
    """A serial session builds an FMU when a test first needs it: say which are stale, so the wait is explained."""
    python, native = _stale()
    if python:
        say(f"FMUs to build (pythonfmu, seconds each) when a test first needs them: {', '.join(python)}")
    if native:
        say(f"native FMUs to build (FMI 2.0 and 3.0 for every target, minutes on a cold zig cache) when a test "
            f"first needs them: {', '.join(model.model_identifier for model in native)}")


def _build_before_the_workers_start(say):
    """Under pytest-xdist (-n), the controller builds what is stale once, before its workers start:
    otherwise each worker would build the same FMUs at once (safe, as every build replaces its file whole,
    but twice the work).  It says what it builds, one line per FMU, before it builds it."""
    import time as clock

    from harness.fmu_build import builder as build_fmu
    from harness.fmu_build import native as build_native

    python, native = _stale()
    began = clock.perf_counter()
    if python:
        say(f"building the pythonfmu FMUs before the tests: {', '.join(python)}")
    build_fmu.ensure_built()
    if native:
        say(f"building {len(native)} native FMUs before the tests (a few minutes on a cold zig cache):")

        def announce(model, targets):
            say(f"  {model.model_identifier}: FMI 2.0 and 3.0 for {', '.join(targets)} ({2 * len(targets)} binaries)")

        build_native.ensure_built(announce=announce)
    if python or native:
        say(f"FMUs built in {clock.perf_counter() - began:.0f} s")


def pytest_sessionfinish(session):
    fmi = sys.modules.get("harness.fmi")  # the FMUs it extracted once for the session (harness/fmi.py: extracted_fmu)
    if fmi is not None:
        fmi.release_extractions()


#: {test id: seconds of setup, call and teardown} of every test this session ran that is not marked slow
_FAST_LOOP_SECONDS = {}
#: how many of the fast loop's slowest tests the summary names (docs/ci.md: what belongs in the fast loop)
FAST_LOOP_SHOWN = 10


def pytest_runtest_logreport(report):
    # under pytest-xdist the controller gets every worker's reports, with their keywords
    if "slow" not in report.keywords:
        _FAST_LOOP_SECONDS[report.nodeid] = _FAST_LOOP_SECONDS.get(report.nodeid, 0.0) + report.duration


def fast_loop_summary(seconds: dict, shown: int = FAST_LOOP_SHOWN) -> list:
    """The lines that name the fast loop's slowest tests: the whole suite's run shows what the fast loop costs."""
    if not seconds:
        return []
    slowest = sorted(seconds.items(), key=lambda item: -item[1])[:shown]
    lines = [f"the fast loop (-m 'not slow'): {len(seconds)} tests, {sum(seconds.values()):.1f} s of test time "
             f"in all (setup, call and teardown; collection and the session's FMU builds not counted); "
             f"its {len(slowest)} slowest:"]
    lines += [f"  {duration:7.2f} s  {test_id}" for test_id, duration in slowest]
    return lines


def pytest_terminal_summary(terminalreporter):
    for line in fast_loop_summary(_FAST_LOOP_SECONDS):
        terminalreporter.write_line(line)
    folder = tempfile.gettempdir()
    left = sorted(name for name in set(os.listdir(folder)) - _TEMP_BEFORE if not name.startswith("pytest-of-"))
    if left:
        shown = ", ".join(left[:20]) + (f" and {len(left) - 20} more" if len(left) > 20 else "")
        terminalreporter.write_line(f"temp directory {folder}: {len(left)} new entries since the session started "
                                    f"(left by this run, or by other processes): {shown}", yellow=True)
    else:
        terminalreporter.write_line(f"temp directory {folder}: nothing left behind by this run")
