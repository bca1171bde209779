#include "common.hpp"

#include "db/schema.hpp"
#include "db/store.hpp"
#include "jobs/job_spec.hpp"
#include "jobs/query.hpp"
#include "jobs/runner.hpp"
#include "jobs/job_error.hpp"
#include "jobs/shard.hpp"
#ifdef DEMCAL_HAVE_MPI
#include "jobs/mpi_runner.hpp"
#endif

#include <algorithm>
#include <iostream>
#include <memory>
#include <unistd.h>

namespace demcal::cli {
namespace {

struct RunArgs {
  std::string job, db = "demcal.db", out, format = "table";
  std::string shard;
  bool shard_given = false;
  int workers = 0;
  bool retry_failed = false;
  bool requeue_running = false;
  bool mpi = false;
  double mpi_timeout = 60;
};

int run(const RunArgs& a) {
  const jobs::Format format = jobs::parse_format(a.format);
  const jobs::Shard shard = a.shard_given ? jobs::parse_shard(a.shard) : jobs::Shard{};
  // Validate completely before the database is even opened: an invalid job
  // writes nothing anywhere.
  const jobs::Job job = jobs::load_job_file(a.job);
  print_notes(a.job, job.notes);
  if (a.db.empty()) throw jobs::JobError("--db", "empty path");
  jobs::RunOptions opt;
  opt.out_dir = a.out.empty() ? default_out_dir(a.db) : a.out;
  opt.out_flag = out_flag(a.out);
  opt.shard = shard;
  require_writable_dir(opt.out_flag, opt.out_dir);  // before the database is written
  // The database checked (read-only) and its folder found, then the output folder
  // made, then the database opened: a refusal of either writes nothing.
  db::check_file(a.db);
  db::check_writable(a.db);
  jobs::make_task_output_dir(job, opt);
  db::Store store(a.db);
  opt.workers = a.workers;
  opt.retry_failed = a.retry_failed;
  opt.requeue_running = a.requeue_running;
  opt.terminal = isatty(STDERR_FILENO) != 0;
  opt.log = &std::cerr;
#ifdef DEMCAL_HAVE_MPI
  const jobs::RunSummary s =
      a.mpi ? jobs::mpi::run_job_root(store, job, opt, jobs::mpi::MpiOptions{a.mpi_timeout}) : jobs::run_job(store, job, opt);
#else
  const jobs::RunSummary s = jobs::run_job(store, job, opt);
#endif
  if (!s.database_lost.empty()) {
    std::cerr << "demcal: error: " << s.database_lost << ": " << jobs::lost_database_advice(s) << "\n";
    return kRuntime;
  }
  if (s.superseded) {
    std::cerr << "demcal: error: job " << job.name << " was recorded again from a different job file by another run while "
              << "this one was at work: the job now holds that file's tasks, so this run stopped after the " << s.ran
              << " task(s) it ran (their results are kept: demcal query --db " << a.db
              << " --where task=ID). Give one of the two jobs another name to keep both\n";
    return kRuntime;
  }
  std::vector<jobs::ResultRow> rows = jobs::select_rows(store, job.name, {});
  // A shard shows its own part, as it counts it: other shards may share the database.
  rows.erase(std::remove_if(rows.begin(), rows.end(),
                            [&](const jobs::ResultRow& r) { return !shard.contains(static_cast<std::size_t>(r.task.index)); }),
             rows.end());
  const int hidden = jobs::print_rows(std::cout, rows, {}, format);
  if (hidden > 0)
    std::cout << "(" << hidden << " more metrics per task: demcal query --db " << a.db << " --job " << job.name
              << " --metrics all, or --format csv or json"
              << (shard.active() ? "; both list the tasks of every shard in that database" : "") << ")\n";
  std::cerr << "job " << job.name << (shard.active() ? " shard " + shard.label() : std::string()) << ": " << s.done << " done (" << s.reused << " reused), " << s.failed << " failed, "
            << s.unfinished << " unfinished, of " << s.total << "\n";
  // The hint repeats what selects this run's tasks and files: without --shard it
  // would run the whole grid into a shard's part.
  const std::string same = " --db " + a.db + (shard.active() ? " --shard " + shard.label() : std::string()) +
                           (a.out.empty() ? std::string() : " --out " + a.out);
  if (s.failed > 0 && !s.interrupted)
    std::cerr << "why they failed: demcal status --db " << a.db << " --job " << job.name
              << "; to run them again: demcal run " << a.job << same << " --retry-failed\n";
  if (!s.output_failure.empty())
    std::cerr << "demcal: error: stopped: " << s.output_failure << ". That task and those not yet started are "
              << "pending; free space in (or fix) the output folder " << jobs::task_output_dir(job, opt)
              << ", then: demcal run " << a.job << same << "\n";
  else if (s.unfinished > 0 && !s.interrupted)
    std::cerr << "unfinished tasks are held by another runner (demcal status --db " << a.db
              << "); if none is at work on them any more: demcal run " << a.job << same << " --requeue-running\n";
  if (s.interrupted || s.failed > 0 || s.unfinished > 0 || !s.output_failure.empty()) return kRuntime;
  return kOk;
}

}  // namespace

void add_run(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand("run", "Run a job's tasks (resumes: finished tasks are reused)");
  auto a = std::make_shared<RunArgs>();
  cmd->add_option("JOB", a->job, "job file (JSON)")->required()->check(kPlainPath);
  cmd->add_option("--db", a->db, "SQLite database")->check(kDbPath)->capture_default_str();
  cmd->add_option("--workers", a->workers, "worker processes (default: the core count)")->transform(kWholeNumber)->check(CLI::Range(1, 4096));
  cmd->add_option("--out", a->out, "output directory (default: demcal-out/ next to the database)")->check(kPlainPath);
  cmd->add_flag("--retry-failed", a->retry_failed, "run the job's failed tasks again");
  cmd->add_flag("--requeue-running", a->requeue_running,
                "put the job's running tasks back in the queue first: their runner is gone (a runner on another "
                "host that stopped beating is found out by itself after 120 s)");
  cmd->add_option("--format", a->format, "results on stdout: table, csv or json")->capture_default_str();
  auto* shard_opt = cmd->add_option("--shard", a->shard,
                  "run only shard i of N (1-based): the tasks whose expansion index k has k mod N = i-1; "
                  "join the parts' databases with demcal merge");
  cmd->add_flag("--mpi", a->mpi,
                "MPI task farm under mpirun: rank 0 owns the database and hands out tasks, the other ranks run them");
  auto* timeout_opt = cmd->add_option("--mpi-timeout", a->mpi_timeout,
                  "with --mpi: seconds without a heartbeat after which a worker rank counts as lost")
      ->capture_default_str()
      ->check(kFinite)
      ->check(CLI::Range(0.1, 86400.0));
  cmd->callback([a, shard_opt, timeout_opt, &exit_code] {
    a->shard_given = shard_opt->count() > 0;
    if (!a->mpi && timeout_opt->count() > 0) {  // a farm's option on a local run: a command line mixed up
      std::cerr << "demcal: error: --mpi-timeout: applies to an MPI run only (--mpi under mpirun)\n";
      exit_code = kBadInput;
      return;
    }
    if (!a->mpi) {
      if (a->shard_given) {  // a bad --shard is the command line's fault, not the job file's
        exit_code = guarded("", [&] { return jobs::parse_shard(a->shard).active() ? kOk : kBadInput; });
        if (exit_code != kOk) return;
      }
      exit_code = guarded(a->job, [&] { return run(*a); });
      return;
    }
#ifdef DEMCAL_HAVE_MPI
    // Every rank runs this; only rank 0 reads the job file and opens the database.
    jobs::mpi::Session session;
    if (session.rank() != 0) {
      exit_code = jobs::mpi::serve(jobs::mpi::MpiOptions{a->mpi_timeout});
      return;
    }
    if (session.size() < 2) {
      std::cerr << "demcal: error: --mpi needs at least 2 ranks: rank 0 coordinates and the others run tasks "
                   "(mpirun -n 3 demcal run JOB --mpi)\n";
      exit_code = kBadInput;
      return;
    }
    exit_code = guarded(a->job, [&] { return run(*a); });
#else
    std::cerr << "demcal: error: --mpi: this demcal was built without MPI (configure with -DDEMCAL_MPI=ON; "
                 "needs OpenMPI: libopenmpi-dev); use --shard i/N and demcal merge instead\n";
    exit_code = kBadInput;
#endif
  });
}

}  // namespace demcal::cli
