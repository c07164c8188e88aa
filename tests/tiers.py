"""The suite's two tiers: which tests are ``slow``, and the quick test that stands for each.

The README's test command runs the quick tier (``-m "not slow"``, about ten minutes on two cores);
``.ci/run`` runs it and then the slow tier (``-m slow``), so CI runs every test. A test is slow
here when it repeats, at more seeds, sizes or failure modes, what a quick test already checks: the
long statistical simulations (a calibration per data set, coverage over many draws), live-server
fault scenarios (restarts, Dask faults, two servers, floods), browser walks, and the spec's fuzz and
stateful phases. Each entry names the quick test that checks the same behaviour, so the quick tier
still touches every feature; ``tests/conftest.py`` marks the entries and fails the collection when
an entry or its stand-in no longer names a collected test, or when a stand-in is itself slow.

Keys and stand-ins are node ids under ``tests/``; a key without ``[...]`` covers every
parametrization of the test, and a file of SLOW_FILES every test in it.
"""

from __future__ import annotations

#: test file -> the quick test that checks the same behaviour: every test of the file is slow, and a
#: run that deselects the slow tier does not collect the file (its collection is itself slow)
SLOW_FILES: dict[str, str] = {
    "test_service_schemathesis_fuzz.py":
        "test_service_schemathesis.py::test_every_request_example_of_the_spec_is_accepted",
}

#: node id -> the quick test that checks the same behaviour
SLOW: dict[str, str] = {
    # --- the spec: fuzz and stateful phases (one worker for ~20 minutes together) ---
    "test_service_schemathesis_links.py::test_linked_requests_reach_every_id_route":
        "test_service_schemathesis_links.py::test_every_id_route_is_the_target_of_a_link_that_resolves",
    # --- calibration: more drivers, seeds and data sets of the same searches ---
    "test_calibrate_seams_intervals.py::test_replicated_runs_at_the_far_end_of_a_driver_narrow_the_interval_there_and_it_covers":
        "test_calibrate_seams_intervals.py::test_only_the_folds_that_chose_other_terms_are_predicted_again_and_by_the_chosen_terms",
    "test_calibrate.py::test_hidden_effect_is_found_on_its_driver_and_cuts_the_error_threefold[cycle]":
        "test_calibrate.py::test_hidden_effect_is_found_on_its_driver_and_cuts_the_error_threefold"
        "[relative_humidity]",
    "test_calibrate.py::test_hidden_effect_is_found_on_its_driver_and_cuts_the_error_threefold[vibration_um]":
        "test_calibrate.py::test_hidden_effect_is_found_on_its_driver_and_cuts_the_error_threefold"
        "[relative_humidity]",
    "test_calibrate_level_drift.py::test_a_viscosity_wrong_by_eight_is_said_to_be_a_level_not_a_drift_with_humidity":
        "test_calibrate_level_drift.py::test_a_drift_whose_coefficient_shows_no_change_is_named_for_its_level",
    "test_calibrate.py::test_a_drifting_parameter_is_named_with_its_driver":
        "test_calibrate.py::test_hidden_effect_is_found_on_its_driver_and_cuts_the_error_threefold"
        "[relative_humidity]",
    "test_calibrate.py::test_two_effects_are_both_found_through_gross_outliers":
        "test_calibrate.py::test_hidden_effect_is_found_on_its_driver_and_cuts_the_error_threefold"
        "[relative_humidity]",
    "test_calibrate.py::test_nested_error_exposes_the_selection_bias_of_a_spurious_effect":
        "test_calibrate_select.py::test_the_threshold_is_reproducible_and_the_selection_uses_it_within_the"
        "_bonferroni_bound",
    "test_calibrate.py::test_noise_alone_adds_nothing[False]":
        "test_calibrate.py::test_noise_alone_adds_nothing[True]",
    "test_calibrate.py::test_a_gp_on_what_the_terms_leave_joins_the_model_and_widens_its_intervals":
        "test_calibrate.py::test_the_stored_gp_predicts_as_scikit_learn_does",
    "test_calibrate_honest.py::test_a_gp_that_only_fills_what_some_folds_missed_does_not_join_a_correct_model":
        "test_calibrate.py::test_the_stored_gp_predicts_as_scikit_learn_does",
    "test_calibrate_trust.py::test_heavy_tailed_scatter_is_covered_through_the_api":
        "test_calibrate_trust.py::test_ten_rows_are_answered_with_an_allowance_and_no_effect_claimed",
    "test_calibrate_trust.py::test_few_rows_cover_within_the_band_over_data_sets":
        "test_calibrate_trust.py::test_ten_rows_are_answered_with_an_allowance_and_no_effect_claimed",
    "test_calibrate_groups.py::test_a_law_the_score_held_back_on_the_column_that_moved_with_speed_is_kept_where"
    "_the_columns_part":
        "test_calibrate_confounded_select.py::test_a_close_call_between_confounded_drivers_names_both_the_law_first",
    "test_calibrate_groups.py::test_speed_and_temperature_that_move_together_are_named_and_the_empty_corner_is_out"
    "_of_the_domain":
        "test_calibrate_confounded_select.py::test_a_close_call_between_confounded_drivers_names_both_the_law_first",
    "test_calibrate_groups.py::test_off_the_data_a_term_on_the_column_that_moved_with_speed_holds_the_other"
    "_explanation":
        "test_calibrate_groups.py::test_off_line_difference_is_the_log_ratio_on_the_rows_with_the_rivals_driver"
        "_reflected",
    "test_calibrate_groups.py::test_a_new_groups_interval_holds_90_percent_in_almost_every_data_set":
        "test_calibrate_groups.py::test_builds_of_one_bearing_give_their_spread_and_intervals_that_cover_known_and"
        "_new_builds",
    "test_calibrate_groups.py::test_labels_and_declared_codes_calibrate_through_the_api_and_name_groups_in"
    "_predictions":
        "test_calibrate_groups.py::test_a_column_of_labels_is_a_factor_and_integer_codes_only_when_declared",
    "test_calibrate_groups.py::test_scatter_ten_percent_below_20_mm_s_gives_intervals_that_cover_each_region":
        "test_calibrate_groups.py::test_scatter_model_finds_a_step_in_speed_and_stays_constant_on_one_spread",
    "test_calibrate_scatter.py::test_a_calibration_on_scatter_that_grows_with_the_load_covers_every_region_of"
    "_the_load":
        "test_calibrate_groups.py::test_scatter_model_finds_a_step_in_speed_and_stays_constant_on_one_spread",
    "test_calibrate_scatter.py::test_the_allowance_brings_a_fitted_log_linear_spread_to_its_coverage_at_the"
    "_noisy_end":
        "test_calibrate_trust.py::test_ten_rows_are_answered_with_an_allowance_and_no_effect_claimed",
    "test_calibrate_honest.py::test_rival_laws_hold_their_disagreement_at_80_rh_and_leave_the_data_alone":
        "test_calibrate_honest.py::test_an_optimization_with_a_calibrated_model_answers_the_rivals_envelope",
    "test_calibrate_honest.py::test_friction_and_batch_answer_the_envelope_of_the_stored_rivals":
        "test_calibrate_honest.py::test_an_optimization_with_a_calibrated_model_answers_the_rivals_envelope",
    "test_calibrate_honest.py::test_clean_data_leave_nothing_undecided":
        "test_calibrate.py::test_noise_alone_adds_nothing[True]",
    "test_calibrate_honest.py::test_a_viscosity_drift_fits_its_level_and_the_activation_energy_comes_out_near"
    "_truth":
        "test_calibrate_honest.py::test_a_level_drift_screened_to_first_order_matches_the_physics",
    "test_calibrate_honest.py::test_a_run_in_too_few_rows_can_show_is_said_with_where_more_rows_would_settle_it":
        "test_calibrate.py::test_noise_alone_adds_nothing[True]",
    "test_calibrate_weighted_select.py::test_weighted_selection_finds_a_drag_that_the_unweighted_one_misses":
        "test_calibrate_weighted_select.py::test_a_missed_effect_is_not_taken_for_scatter",
    "test_calibrate_weighted_select.py::test_weighted_selection_adds_nothing_where_there_is_nothing":
        "test_calibrate_weighted_select.py::test_a_missed_effect_is_not_taken_for_scatter",
    "test_calibrate_weighted_select.py::test_the_weights_follow_the_generating_scatter":
        "test_calibrate_weighted_select.py::test_declared_noise_weighs_the_rows_and_the_search_runs_once",
    "test_calibrate.py::test_scatter_above_the_declared_noise_is_said":
        "test_calibrate_weighted_select.py::test_declared_noise_weighs_the_rows_and_the_search_runs_once",
    "test_calibrate_api.py::test_csv_upload_with_fixed_values_and_noise_alone":
        "test_intake_spreadsheets.py::test_an_excel_export_uploaded_as_a_form_calibrates_like_the_clean_file",
    "test_service_whole_counts.py::test_calibration_rows_with_counts_written_with_fractions_fit_as_the_counts":
        "test_service_whole_counts.py::test_a_batch_column_of_counts_written_with_fractions_is_the_column_of_counts",
    "test_seams_integer_columns.py::test_a_ball_count_effect_calibrates_with_its_plots_through_the_api":
        "test_seams_integer_columns.py::test_a_ball_count_effect_calibrates_with_its_plots_through_the_cli",
    "test_seams_domain_edges.py::test_a_viscous_power_law_predicts_at_rest":
        "test_seams_domain_edges.py::test_a_run_in_predicts_at_zero[time_h-10.0-1.5]",
    "test_calibrate_confounded_select.py::test_the_viscosity_law_is_named_when_it_is_strong_enough":
        "test_calibrate_confounded_select.py::test_a_close_call_between_confounded_drivers_names_both_the_law_first",
    "test_calibrate_api.py::test_a_surrogate_of_a_calibration_with_fixed_values_inherits_them":
        "test_calibrate_api.py::test_a_surrogate_learns_the_calibrated_model",
    "test_calibrate_api.py::test_cli_prints_the_report_and_writes_plots_and_json":
        "test_seams_integer_columns.py::test_a_ball_count_effect_calibrates_with_its_plots_through_the_cli",
    "test_calibrate_tabular.py::test_api_takes_a_stated_dialect_and_json_rows_with_units":
        "test_intake_spreadsheets.py::test_an_excel_export_uploaded_as_a_form_calibrates_like_the_clean_file",
    "test_columns_seams.py::test_percent_humidity_at_prediction_is_refused_as_the_upload_refuses_it":
        "test_columns_seams.py::test_the_upload_s_headers_and_other_units_are_converted_at_prediction",
    "test_seams_domain_edges.py::test_a_run_in_measured_from_the_first_cycle_predicts_at_zero":
        "test_seams_domain_edges.py::test_a_run_in_predicts_at_zero[time_h-10.0-1.5]",
    "test_seams_domain_edges.py::test_a_run_in_predicts_at_zero[cycles-2000.0-300.0]":
        "test_seams_domain_edges.py::test_a_run_in_predicts_at_zero[time_h-10.0-1.5]",
    "test_seams_replicates.py::test_a_replicated_design_predicts_with_intervals_that_cover_the_truth":
        "test_calibrate_measurement.py::test_replicates_through_the_api",
    "test_surrogate.py::test_calibration_is_nominal_when_the_errors_are_known[rms-kfold]":
        "test_surrogate.py::test_calibration_is_nominal_when_the_errors_are_known[central-loo]",
    "test_surrogate.py::test_calibration_is_nominal_when_the_errors_are_known[rms-loo]":
        "test_surrogate.py::test_calibration_is_nominal_when_the_errors_are_known[central-loo]",
    "test_surrogate.py::test_quantile_upper_bound_covers_the_true_quantile_and_tightens_with_n":
        "test_surrogate.py::test_quantile_upper_bound_by_order_statistics",
    "test_surrogate.py::test_sobol_indices_of_the_ishigami_function":
        "test_surrogate.py::test_sobol_indices_of_an_additive_function",
    "test_surrogate.py::test_calibration_is_nominal_when_the_errors_are_known[central-kfold]":
        "test_surrogate.py::test_calibration_is_nominal_when_the_errors_are_known[central-loo]",
    # --- experiments, designs and the shell loop: whole manual walks ---
    "test_experiments.py::test_the_manual_loop_runs_and_prints_what_it_says":
        "test_experiments.py::test_discriminate_goes_where_the_rivals_part",
    "test_experiments_promise.py::test_the_proposed_runs_shrink_the_reported_interval_as_much_as_they_promise":
        "test_experiments.py::test_parameters_and_predict_shrink_what_they_target",
    "test_experiments.py::test_the_rivals_of_a_kelvin_drift_include_the_linear_law":
        "test_experiments.py::test_a_rival_carries_its_own_scatter_and_the_models_data_cloud",
    "test_experiments_api.py::test_discriminate_proposes_runs_where_the_humidity_laws_part":
        "test_experiments_api.py::test_predict_narrows_the_interval_over_the_envelope",
    "test_optimize_robust_api.py::test_the_designers_request_on_a_calibrated_model":
        "test_optimize_robust_api.py::test_the_manual_example_gives_the_figures_it_shows",
    "test_optimize_robust_api.py::test_calibrated_conditions_are_named_when_missing_or_unknown":
        "test_optimize_robust_api.py::test_the_manual_example_gives_the_figures_it_shows",
    "test_optimize_toy_law.py::test_a_toy_law_is_found_by_calibration_and_its_robust_design_reads_its_declarations":
        "test_optimize_toy_law.py::test_registering_checks_the_declarations",
    "test_cli_loop.py::test_a_lab_calibrates_predicts_plans_designs_and_deletes_from_the_shell":
        "test_experiments_api.py::test_cli_first_design_and_next_runs_of_a_stored_calibration",
    "test_plots_ticks.py::test_every_calibration_plot_is_numbered_on_every_axis":
        "test_plots_ticks.py::test_the_plots_speak_the_upload_s_units_and_count_balls_in_whole_numbers",
    # --- the service: live-server fault scenarios, browsers, packaging ---
    "test_reliability_restart.py::test_queued_jobs_stay_queued_and_run_after_a_restart":
        "test_reliability_restart.py::test_a_job_that_ends_within_the_grace_period_finishes_before_the_process_exits",
    "test_reliability_crash.py::test_sigkill_during_jobs_loses_nothing":
        "test_reliability_crash.py::test_sigkill_while_writing_models_leaves_only_whole_models",
    "test_reliability_dask.py::test_a_real_cluster_answers_as_the_local_pool_and_survives_a_killed_worker":
        "test_reliability_dask_hang.py::test_the_readme_worker_outlives_a_scheduler_restart",
    "test_reliability_dask_faults.py::test_a_lost_scheduler_or_worker_fails_in_time_and_the_service_reconnects":
        "test_reliability_dask_hang.py::test_the_readme_worker_outlives_a_scheduler_restart",
    "test_reliability_dask_hang.py::test_a_stopped_worker_fails_its_job_in_time_and_readyz_says_so":
        "test_reliability_dask_hang.py::test_the_readme_worker_outlives_a_scheduler_restart",
    "test_reliability_scaleout.py::test_two_uvicorn_workers_share_limits_and_recover_a_killed_workers_job":
        "test_store_backends.py::test_admission_limits_hold_across_stores_under_contention[sqlite]",
    "test_reliability_scaleout.py::test_limits_and_cancellation_hold_across_two_servers":
        "test_store_backends.py::test_leases_cancels_and_deletes_across_stores[sqlite]",
    "test_reliability_scaleout.py::test_a_stopped_servers_job_is_taken_over_within_the_lease_and_a_killed_ones"
    "_at_once":
        "test_store_backends.py::test_each_job_is_claimed_once_among_many_claimers[sqlite]",
    "test_reliability_workers.py::test_two_workers_share_metrics_and_keys":
        "test_store_backends.py::test_admission_limits_hold_across_stores_under_contention[sqlite]",
    "test_reliability_postgres.py::test_two_servers_on_one_postgresql_database":
        "test_store_backends.py::test_each_job_is_claimed_once_among_many_claimers[postgresql]",
    "test_store_backends.py::test_a_server_outage_is_a_503_storage_problem_and_service_resumes_after":
        "test_store_backends.py::test_an_unreachable_server_at_start_is_named_without_the_password",
    "test_reliability_races.py::test_concurrent_deletes_of_queued_running_and_finished_jobs":
        "test_reliability_races.py::test_concurrent_deletes_of_one_surrogate",
    "test_reliability_connections.py::test_header_limits_and_a_connection_flood_on_a_live_server":
        "test_reliability_connections.py::test_requests_past_the_concurrency_limit_get_503_and_probes_pass",
    "test_reliability_proxy.py::test_the_example_nginx_configuration_in_front_of_a_live_server":
        "test_reliability_connections.py::test_a_head_not_finished_in_time_closes_the_connection",
    "test_reliability_storage.py::test_the_server_exits_non_zero_on_a_bad_data_folder":
        "test_reliability_storage.py::test_a_bad_data_folder_is_refused_naming_the_path_and_the_fix[file]",
    "test_service_erasure.py::test_deleting_a_calibration_erases_its_rows_from_every_job_and_the_files[postgresql]":
        "test_service_erasure.py::test_deleting_a_calibration_erases_its_rows_from_every_job_and_the_files[sqlite]",
    "test_service_live.py::test_curl_examples[how-to/labs.md:balls-load_N-speed_m_s-specimen-mu_measu]":
        "test_service_live.py::test_curl_examples[README.md:balls-load-mN-speed-mm-s-relative-humidi]",
    "test_reliability_hostile.py::test_malformed_bodies_get_4xx_problems_everywhere"
    "[an array of 20 million items]":
        "test_reliability_hostile.py::test_malformed_bodies_get_4xx_problems_everywhere[30 MB of spaces]",
    "test_service_client.py::test_operation_through_the_generated_client[create_calibration]":
        "test_service_client.py::test_operation_through_the_generated_client[create_calibration_from_csv]",
    "test_service_client.py::test_operation_through_the_generated_client[create_next_experiments]":
        "test_service_client.py::test_operation_through_the_generated_client[create_first_experiments]",
    "test_service_live.py::test_curl_examples[reference/rest-api.md:balls-load_N-speed_m_s-relative_humidity]":
        "test_service_live.py::test_curl_examples[README.md:balls-load-mN-speed-mm-s-relative-humidi]",
    "test_service_pages.py::test_calibrations_and_surrogates_are_listed_a_page_at_a_time_newest_first":
        "test_service_resources.py::test_calibrations_are_listed_and_deleted_by_their_owner_or_the_admin",
    "test_service_docs.py::test_swagger_ui_and_redoc_render_every_operation_without_network":
        "test_service_docs.py::test_doc_pages_load_only_local_assets[/docs]",
    "test_docs_site.py::test_the_manual_runs_its_scripts_and_searches_in_a_browser":
        "test_docs_site.py::test_the_site_builds_in_strict_mode_without_a_warning",
    "test_web_page.py::test_the_loop_in_chromium_with_api_keys_on":
        "test_web_page.py::test_the_page_is_open_with_keys_on_and_the_api_is_not",
    "test_packaging.py::test_wheel_in_a_fresh_venv_beside_a_package_named_surrogate":
        "test_packaging.py::test_every_package_folder_is_installed",
}


def slow_key(nodeid: str) -> str | None:
    """The entry of SLOW, or file of SLOW_FILES, that covers ``nodeid`` (a node id under ``tests/``)."""
    file, bare = nodeid.split("::", 1)[0], nodeid.split("[", 1)[0]
    return next((key for key in (nodeid, bare) if key in SLOW), file if file in SLOW_FILES else None)
