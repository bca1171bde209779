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
  // CLI11's own refusals (an unknown option, a value out of range) read like
  // demcal's: one "demcal: error:" line, then where the help for that command is.
  app.failure_message([](const CLI::App* top, const CLI::Error& e) {
    const auto chosen = top->get_subcommands();
    const std::string help = chosen.empty() ? "demcal --help" : "demcal " + chosen.front()->get_name() + " --help";
    return "demcal: error: " + std::string(e.what()) + "\n(" + help + " lists the options)\n";
  });
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
  // CLI11 says "A subcommand is required" of a mistyped one: name it and list them.
  if (argc > 1 && argv[1][0] != '-') {
    std::string names;
    bool known = false;
    for (const CLI::App* sub : app.get_subcommands([](CLI::App*) { return true; })) {
      names += (names.empty() ? "" : ", ") + sub->get_name();
      known = known || sub->get_name() == argv[1];
    }
    if (!known) {
      std::cerr << "demcal: error: unknown command \"" << argv[1] << "\" (the commands: " << names
                << ")\n(demcal --help lists them)\n";
      return demcal::cli::kBadInput;
    }
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);  // prints help or the usage error
    return code == 0 ? demcal::cli::kOk : demcal::cli::kBadInput;
  }
  return exit_code;
}
