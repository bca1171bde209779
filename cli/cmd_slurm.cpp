#include "common.hpp"

#include "db/schema.hpp"
#include "jobs/job_error.hpp"
#include "jobs/job_spec.hpp"
#include "jobs/part_file.hpp"
#include "jobs/shard.hpp"

#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <regex>
#include <sys/stat.h>
#include <utility>

namespace demcal::cli {
namespace {

namespace fs = std::filesystem;

struct SlurmArgs {
  std::string job, partition, time, out, db = "demcal.db", parts, demcal;
  int array = 0, cpus = 1;
};

// 'text' for bash, whatever it holds.
std::string quote(const std::string& text) {
  std::string q = "'";
  for (char c : text) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

// The shards' log pattern for an #SBATCH --output line. sbatch reads a directive's
// argument up to a blank unless it is quoted, takes backslash escapes, ends it at an
// unquoted '#', and expands '%' patterns; so the folder is double-quoted with quotes
// escaped and '%' doubled, and a project folder like "My Runs" works. (A backslash
// is refused before: in a filename pattern it turns every expansion off.)
std::string sbatch_output_line(const fs::path& parts) {
  std::string q = "\"";
  for (char c : parts.string()) {
    if (c == '"') q += '\\';
    if (c == '%') q += '%';
    q += c;
  }
  return "#SBATCH --output=" + q + "/slurm-%x-%A_%a.out\"";
}

void check_token(const std::string& option, const std::string& value, const char* pattern, const char* what) {
  if (!value.empty() && !std::regex_match(value, std::regex(pattern)))
    throw jobs::JobError(option, std::string("expected ") + what + ", got \"" + value + "\"");
}

// Where the shards' databases and logs go: --parts, or parts/ beside the database.
fs::path parts_folder(const SlurmArgs& a) {
  return a.parts.empty() ? fs::absolute(a.db).lexically_normal().parent_path() / "parts" : fs::absolute(a.parts).lexically_normal();
}

// The script's first two lines: refuse_to_overwrite knows an earlier script by them.
constexpr const char* kShebang = "#!/usr/bin/env bash";
constexpr const char* kHeader = "# SLURM array job for demcal job";

// The paths the script names, absolute: it changes into the database's folder before
// running anything.
struct ScriptPaths {
  std::string demcal;
  fs::path job, db, workdir, parts;
};

// The options were checked as typed; made absolute from the current folder, a
// newline in its path would end a line of the script (#SBATCH --output, the quoted
// variables) and the script would not even parse: refused, naming the option.
ScriptPaths script_paths(const SlurmArgs& a) {
  ScriptPaths p;
  p.demcal = a.demcal.empty() ? fs::read_symlink("/proc/self/exe").string() : fs::weakly_canonical(fs::absolute(a.demcal)).string();
  p.job = fs::absolute(a.job).lexically_normal();
  p.db = fs::absolute(a.db).lexically_normal();
  p.workdir = p.db.parent_path();
  p.parts = parts_folder(a);
  for (const auto& [flag, path] : {std::pair{std::string("--db"), p.db.string()},
                                   std::pair{std::string(a.parts.empty() ? "--db" : "--parts"), p.parts.string()},
                                   std::pair{std::string("JOB"), p.job.string()}, std::pair{std::string("--demcal"), p.demcal}})
    if (const std::string why = plain_path_error(path); !why.empty())
      throw jobs::JobError(flag, path + ": " + why + " (a relative path takes the current folder's; run demcal slurm from "
                                 "another folder, or give the path whole)");
  return p;
}

std::string script(const SlurmArgs& a, const jobs::Job& job, const ScriptPaths& paths) {
  const std::string& demcal = paths.demcal;
  const fs::path& db = paths.db;
  const fs::path& workdir = paths.workdir;
  const fs::path& parts = paths.parts;
  const std::string n = std::to_string(a.array);
  std::ostringstream s;
  s << kShebang << "\n"
    << kHeader << " \"" << job.name << "\": " << job.tasks.size() << " task(s) in " << n
    << " shard(s), then a merge.\n"
    << "# Written by `demcal slurm`. Submit both steps with:   bash " << (a.out.empty() ? "THIS_SCRIPT" : a.out) << "\n"
    << "#   shard i (array element i, 1-based) runs the tasks whose index k has k mod " << n << " = i-1\n"
    << "#   into its own database; the merge job starts when every shard succeeded\n"
    << "#   (--dependency=afterok) and joins them with `demcal merge`.\n"
    << "# Steps by hand (no SLURM): SLURM_ARRAY_TASK_ID=i bash THIS_SCRIPT shard, then bash THIS_SCRIPT merge.\n"
    << "# A shard with a failed task exits 1 and holds the merge back; rerun it with\n"
    << "#   sbatch --array=i THIS_SCRIPT shard --retry-failed   (or merge anyway: bash THIS_SCRIPT merge);\n"
    << "# a shard stopped by a full disk left its tasks pending: sbatch --array=i THIS_SCRIPT shard\n"
    << "#SBATCH --job-name=demcal-" << job.name << "\n";
  if (!a.partition.empty()) s << "#SBATCH --partition=" << a.partition << "\n";
  if (!a.time.empty()) s << "#SBATCH --time=" << a.time << "\n";
  s << "#SBATCH --ntasks=1\n"
    << "#SBATCH --cpus-per-task=" << a.cpus << "\n"
    << sbatch_output_line(parts) << "\n"
    << "set -euo pipefail\n"
    << "DEMCAL=" << quote(demcal) << "\n"
    << "JOB=" << quote(paths.job.string()) << "\n"
    << "WORKDIR=" << quote(workdir.string()) << "\n"
    << "PARTS=" << quote(parts.string()) << "\n"
    << "DB=" << quote(db.string()) << "\n"
    << "N=" << n << "\n"
    << "SCRIPT=$(readlink -f \"$0\")\n"
    << "cd \"$WORKDIR\"\n"
    << "case \"${1:-submit}\" in\n"
    << "  submit)\n"
    << "    mkdir -p \"$PARTS\"\n"
    << "    array_id=$(sbatch --parsable --array=1-\"$N\" \"$SCRIPT\" shard)\n"
    << "    array_id=${array_id%%;*}  # --parsable prints id[;cluster]\n"
    << "    # The merge is no array job: its log by job id (%a would read 4294967294); '%' in the folder doubled.\n"
    << "    merge_id=$(sbatch --parsable --dependency=afterok:\"$array_id\" --cpus-per-task=1 "
       "--output=\"${PARTS//%/%%}/slurm-%x-merge-%j.out\" \"$SCRIPT\" merge)\n"
    << "    echo \"submitted the shards as job $array_id (array 1-$N) and the merge as job ${merge_id%%;*}\"\n"
    << "    ;;\n"
    << "  shard)\n"
    << "    shift  # anything after \"shard\" goes to demcal run, e.g. --retry-failed\n"
    << "    ID=${SLURM_ARRAY_TASK_ID:?the shard step runs inside a SLURM array job (SLURM_ARRAY_TASK_ID)}\n"
    << "    mkdir -p \"$PARTS\"\n"
    << "    exec \"$DEMCAL\" run \"$JOB\" --shard \"$((ID))/$N\" --db \"$PARTS/part-$ID.db\" --out \"$WORKDIR/demcal-out\" "
       "--workers \"${SLURM_CPUS_PER_TASK:-"
    << a.cpus << "}\" --format csv \"$@\"\n"
    << "    ;;\n"
    << "  merge)\n"
    << "    parts=()\n"
    << "    for ((i = 1; i <= N; i++)); do parts+=(\"$PARTS/part-$i.db\"); done\n"
    << "    exec \"$DEMCAL\" merge \"${parts[@]}\" --into \"$DB\"\n"
    << "    ;;\n"
    << "  *)\n"
    << "    echo \"usage: $0 [submit|shard|merge]\" >&2\n"
    << "    exit 2\n"
    << "    ;;\n"
    << "esac\n";
  return s.str();
}

// The script may replace an earlier script of demcal's, nothing else: --out given as
// the database or the job file (a slip of the hand) would destroy the results.
void refuse_to_overwrite(const SlurmArgs& a) {
  std::error_code ec;
  // The database need not exist yet: the script at its path would be found by the
  // merge, after every shard ran, as "not a SQLite database".
  std::error_code ec_out, ec_db;
  const fs::path out_path = fs::weakly_canonical(fs::absolute(a.out), ec_out);
  const fs::path db_path = fs::weakly_canonical(fs::absolute(a.db), ec_db);
  if (!ec_out && !ec_db && out_path == db_path)
    throw jobs::JobError("--out", a.out + " is the database (--db) the shards merge into; the script needs a name of its own");
  if (!fs::exists(a.out, ec)) return;
  for (const auto& [other, what] : {std::pair{a.db, "the database (--db)"}, std::pair{a.job, "the job file"}})
    if (fs::exists(other, ec) && fs::equivalent(a.out, other, ec))
      throw jobs::JobError("--out", a.out + " is " + what + "; the script needs a name of its own");
  std::ifstream in(a.out);
  std::string first, second;
  std::getline(in, first);
  std::getline(in, second);
  if (!fs::is_regular_file(a.out, ec) || first != kShebang || second.rfind(kHeader, 0) != 0)
    throw jobs::JobError("--out", a.out + " exists and is not a script demcal wrote; choose another name or remove it");
}

int slurm(SlurmArgs a) {
  check_token("--partition", a.partition, "[A-Za-z0-9_.,-]{1,200}", "a partition name (letters, digits, _ . , -)");
  check_token("--time", a.time, "[0-9]{1,6}(-[0-9]{1,2})?(:[0-9]{1,2}){0,2}", "a SLURM time limit such as 30, 4:00:00 or 1-12:00:00");
  const jobs::Job job = jobs::load_job_file(a.job);  // the job must be valid before anything is written
  if (a.out.empty()) a.out = "demcal-" + job.name + ".slurm.sh";
  require_writable_file("--out", a.out);
  // The script runs in the database's folder and writes the parts beside it: both
  // must exist when it runs.
  require_writable_file("--db", a.db);
  // The merge at the end must be able to take the shards: a file that is not a
  // demcal database (or is corrupt, or newer) is refused now, not after every shard ran.
  db::check_file(a.db);
  const fs::path parts = parts_folder(a);
  if (fs::exists(parts) && !fs::is_directory(parts))
    throw jobs::JobError(a.parts.empty() ? "--db" : "--parts", parts.string() + " exists and is not a folder (the shards' databases go there)");
  // SLURM reads a backslash anywhere in --output as "expand nothing and drop the
  // backslashes": the log would land elsewhere, every shard in one file.
  if (parts.string().find('\\') != std::string::npos)
    throw jobs::JobError(a.parts.empty() ? "--db" : "--parts",
                         "the parts folder " + parts.string() +
                             " has a backslash in its path, which SLURM's --output patterns cannot carry; choose another");
  if (!a.demcal.empty() && !fs::exists(a.demcal))
    throw jobs::JobError("--demcal", "no such file: " + fs::absolute(a.demcal).string());
  if (!a.demcal.empty() && !fs::is_regular_file(a.demcal))
    throw jobs::JobError("--demcal", fs::absolute(a.demcal).string() + " is not a file (give the demcal executable)");
  refuse_to_overwrite(a);
  const std::string text = script(a, job, script_paths(a));
  // Written beside its name and renamed: a failed write leaves an earlier script whole.
  jobs::PartFile file(a.out);
  {
    std::ofstream f(file.part(), std::ios::trunc);
    f << text;
    f.close();
    if (!f) throw std::runtime_error("cannot write " + a.out);
  }
  ::chmod(file.part().c_str(), 0755);
  file.commit("batch script");
  std::cout << "wrote " << a.out << ": " << job.tasks.size() << " task(s) of job " << job.name << " in " << a.array
            << " shard(s) plus a merge into " << fs::absolute(a.db).lexically_normal().string() << "\nsubmit with: bash " << a.out << "\n";
  if (static_cast<std::size_t>(a.array) > job.tasks.size())
    std::cerr << "note: " << a.array << " shards for " << job.tasks.size() << " task(s): shards " << job.tasks.size() + 1
              << ".." << a.array << " will have nothing to run (--array " << job.tasks.size() << " is enough)\n";
  return kOk;
}

}  // namespace

void add_slurm(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand("slurm", "Write a SLURM array batch script: one shard per array element, then a merge");
  auto a = std::make_shared<SlurmArgs>();
  cmd->add_option("JOB", a->job, "job file (JSON)")->required()->check(kPlainPath);
  cmd->add_option("--array", a->array, "number of shards (array elements 1..N)")
      ->required()
      ->transform(kWholeNumber)->check(CLI::Range(1, jobs::kMaxShards));
  cmd->add_option("--partition", a->partition, "SLURM partition");
  cmd->add_option("--time", a->time, "time limit per shard (SLURM format, e.g. 4:00:00)");
  cmd->add_option("--cpus-per-task", a->cpus, "cores per shard (its local --workers)")
      ->capture_default_str()
      ->transform(kWholeNumber)->check(CLI::Range(1, 4096));
  cmd->add_option("--db", a->db, "the merged database")->check(kDbPath)->capture_default_str();
  cmd->add_option("--parts", a->parts, "folder for the shards' databases and logs (default: parts/ next to --db)")->check(kPlainPath);
  cmd->add_option("--demcal", a->demcal, "demcal executable on the cluster (default: this one)")->check(kPlainPath);
  cmd->add_option("--out", a->out, "script to write (default: demcal-<job>.slurm.sh)")->check(kPlainPath);
  cmd->callback([a, &exit_code] { exit_code = guarded(a->job, [&] { return slurm(*a); }); });
}

}  // namespace demcal::cli
