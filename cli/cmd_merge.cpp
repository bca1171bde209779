#include "common.hpp"

#include "db/merge.hpp"
#include "db/store.hpp"
#include "jobs/stop_signal.hpp"

#include <iostream>
#include <memory>

namespace demcal::cli {
namespace {

struct MergeArgs {
  std::vector<std::string> parts;
  std::string into = "demcal.db";
};

// A merge of parts whose runs were cut short (a shard killed, a SLURM merge that ran
// anyway) succeeds: say what the merged jobs still lack, as status would.
void say_unfinished(const std::string& into) {
  db::Store store(into, /*read_only=*/true);
  for (const auto& [job, by_status] : store.counts()) {
    std::string lacking;
    for (const char* st : {"pending", "running", "failed"})
      if (const auto it = by_status.find(st); it != by_status.end() && it->second > 0)
        lacking += (lacking.empty() ? "" : ", ") + std::to_string(it->second) + " " + st;
    if (!lacking.empty())
      std::cout << "job " << job << " in " << into << " has tasks without a result: " << lacking
                << " (demcal status --db " << into << " says why; a part's run resumes with demcal run)\n";
  }
}

int merge(const MergeArgs& a) {
  // Ctrl-C or SIGTERM ends the merge through its rollback, so nothing is half-written.
  jobs::StopSignalGuard guard;
  const db::MergeReport r = db::merge_databases(a.into, a.parts, [] { return jobs::stop_signal() != 0; });
  std::cout << "merged " << r.parts << " database(s) into " << a.into << ": " << r.jobs_added << " job(s) added, "
            << r.tasks_added << " task(s) added, " << r.results_taken << " result(s) taken, " << r.identical
            << " identical already there, " << r.kept << " kept (the destination's finished result), "
            << r.links_added << " job-task link(s) added, " << r.fits_added << " fit(s) added, "
            << r.conflicts.size() << " conflict(s)\n";
  say_unfinished(a.into);
  for (const auto& c : r.conflicts) std::cerr << "demcal: conflict: " << c << "\n";
  if (!r.conflicts.empty()) {
    std::cerr << "demcal: " << r.conflicts.size()
              << " conflict(s): the same task key with different results; the destination kept its own, "
                 "everything else was merged\n";
    return kRuntime;
  }
  return kOk;
}

}  // namespace

void add_merge(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand(
      "merge", "Join databases of sharded runs (demcal run --shard i/N) into one: one result per task key");
  auto a = std::make_shared<MergeArgs>();
  cmd->add_option("PARTS", a->parts, "databases to merge (e.g. part-*.db)")->required()->check(kDbPath);
  cmd->add_option("--into", a->into, "destination database (created if missing)")->check(kDbPath)->capture_default_str();
  cmd->footer(
      "Identical results already in the destination are left alone, so merging a part twice changes nothing. "
      "The same task key with different metrics is a conflict: reported, the destination keeps its result, exit "
      "code 1. A part that is missing, not a demcal database or of a schema version this demcal does not merge stops the merge before "
      "anything is written (exit code 2); the merge is one transaction, and a new destination is built beside it "
      "and renamed when whole, so a merge stopped or killed part-way leaves no half-made database.");
  cmd->callback([a, &exit_code] { exit_code = guarded("", [&] { return merge(*a); }); });
}

}  // namespace demcal::cli
