// demcal: batch DEM calibration. Thin CLI11 subcommands over the jobs and db layers.
#include "common.hpp"

#include <csignal>
#include <iostream>

int main(int argc, char** argv) {
  // A reader that goes away (`demcal run JOB | head`, a closed terminal, a killed
  // tee) must not kill a run, a study or a merge half-way: writes to it fail
  // quietly, and the work goes on to store its results.
  std::signal(SIGPIPE, SIG_IGN);
  CLI::App app{"demcal: DEM calibration runs, results and maps"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "demcal 0.1.0");
  int exit_code = demcal::cli::kOk;
  demcal::cli::add_validate(app, exit_code);
  demcal::cli::add_run(app, exit_code);
  demcal::cli::add_status(app, exit_code);
  demcal::cli::add_query(app, exit_code);
  demcal::cli::add_plot(app, exit_code);
  demcal::cli::add_map(app, exit_code);
  demcal::cli::add_envelope(app, exit_code);
  demcal::cli::add_fit(app, exit_code);
  demcal::cli::add_merge(app, exit_code);
  demcal::cli::add_slurm(app, exit_code);
  demcal::cli::add_study(app, exit_code);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);  // prints help or the usage error
    return code == 0 ? demcal::cli::kOk : demcal::cli::kBadInput;
  }
  return exit_code;
}
