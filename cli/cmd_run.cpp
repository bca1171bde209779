#include "common.hpp"

#include "db/store.hpp"
#include "jobs/job_spec.hpp"
#include "jobs/query.hpp"
#include "jobs/runner.hpp"

#include <iostream>
#include <unistd.h>

namespace demcal::cli {
namespace {

struct RunArgs {
  std::string job, db = "demcal.db", out, format = "table";
  int workers = 0;
  bool retry_failed = false;
};

int run(const RunArgs& a) {
  const jobs::Format format = jobs::parse_format(a.format);
  // Validate completely before the database is even opened: an invalid job
  // writes nothing anywhere.
  const jobs::Job job = jobs::load_job_file(a.job);
  db::Store store(a.db);
  jobs::RunOptions opt;
  opt.workers = a.workers;
  opt.out_dir = a.out.empty() ? default_out_dir(a.db) : a.out;
  opt.retry_failed = a.retry_failed;
  opt.terminal = isatty(STDERR_FILENO) != 0;
  opt.log = &std::cerr;
  const jobs::RunSummary s = jobs::run_job(store, job, opt);
  jobs::print_rows(std::cout, jobs::select_rows(store, job.name, {}), {}, format);
  std::cerr << "job " << job.name << ": " << s.done << " done (" << s.reused << " reused), " << s.failed << " failed, "
            << s.unfinished << " unfinished, of " << s.total << "\n";
  if (s.interrupted || s.failed > 0 || s.unfinished > 0) return kRuntime;
  return kOk;
}

}  // namespace

void add_run(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand("run", "Run a job's tasks (resumes: finished tasks are reused)");
  auto a = std::make_shared<RunArgs>();
  cmd->add_option("JOB", a->job, "job file (JSON)")->required();
  cmd->add_option("--db", a->db, "SQLite database")->capture_default_str();
  cmd->add_option("--workers", a->workers, "worker processes (default: the core count)")->check(CLI::Range(1, 4096));
  cmd->add_option("--out", a->out, "output directory (default: demcal-out/ next to the database)");
  cmd->add_flag("--retry-failed", a->retry_failed, "run the job's failed tasks again");
  cmd->add_option("--format", a->format, "results on stdout: table, csv or json")->capture_default_str();
  cmd->callback([a, &exit_code] { exit_code = guarded(a->job, [&] { return run(*a); }); });
}

}  // namespace demcal::cli
