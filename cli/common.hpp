#pragma once
// What the subcommands share: exit codes, error reporting and where files live.
#include <CLI/CLI.hpp>

#include <functional>
#include <string>
#include <vector>

namespace demcal::cli {

enum Exit { kOk = 0, kRuntime = 1, kBadInput = 2 };

// Runs a subcommand body, mapping exceptions to a message on stderr and an exit
// code: JobError and bad database files -> 2, everything else -> 1.
int guarded(const std::string& context, const std::function<int()>& body);

// For map and fit run without --job: demcal chose the job, so an error
// JobError("--job", …) raises about it is said without the "--job:" the user did not
// write (the reason names the job). With --job given, errors pass unchanged.
int chosen_job_errors(bool job_given, const std::function<int()>& body);

// The output directory: --out, or demcal-out/ next to the database.
std::string default_out_dir(const std::string& db_path);
// What errors about the output folder name: "--out", or, when --out was not given,
// that the folder is its default beside the database (not the database itself).
std::string out_flag(const std::string& out);
// Throws JobError("--db") when the database does not exist (read-only commands).
void require_db(const std::string& db_path);
// Checks before anything is written, creating nothing: throws JobError(flag) naming
// the path and the reason when the folder (or its nearest existing parent) is not a
// writable folder, or when the file's folder does not exist or is not writable.
void require_writable_dir(const std::string& flag, const std::string& dir);
void require_writable_file(const std::string& flag, const std::string& file);
// Option checks for paths, so that CLI11 names the option and exits 2:
// kPlainPath refuses an empty path, control characters (a newline in a path would
// end a line of the gnuplot and batch scripts demcal writes) and bytes that are not
// UTF-8 (the path goes into JSON records, which must be UTF-8); kDbPath also
// refuses the names SQLite would not read as a file (":memory:", "file:...").
extern const CLI::Validator kPlainPath;
// kPlainPath's check on a path built rather than typed (a relative one made absolute
// from the current folder): "" when plain, else why not.
std::string plain_path_error(const std::string& path);
extern const CLI::Validator kDbPath;
// One line of UTF-8 text (a chart title): gnuplot's title ends at a newline, and
// the SVG must be valid.
extern const CLI::Validator kOneLine;
// Not empty: `--job ''` read as no filter at all, `--x ''` as the default column.
extern const CLI::Validator kNonEmpty;
// A finite number: CLI11's ranges let NaN through.
extern const CLI::Validator kFinite;
extern const CLI::Validator kTaskId;  // a positive int64 in decimal; attach with transform()
// A whole number written in decimal, handed on to the range check in plain decimal:
// CLI11 reads integers with strtoll(…, 0), so "--workers 010" was octal 8 and 0x10
// was 16. Attach with transform() before the range check.
extern const CLI::Validator kWholeNumber;
extern const CLI::Validator kPositiveFinite;

// A job's notes (legal but easy to miss) on stderr, one line each.
void print_notes(const std::string& job_file, const std::vector<std::string>& notes);

void add_validate(CLI::App& app, int& exit_code);
void add_run(CLI::App& app, int& exit_code);
void add_status(CLI::App& app, int& exit_code);
void add_query(CLI::App& app, int& exit_code);
void add_plot(CLI::App& app, int& exit_code);
void add_map(CLI::App& app, int& exit_code);
void add_envelope(CLI::App& app, int& exit_code);
void add_fit(CLI::App& app, int& exit_code);
void add_merge(CLI::App& app, int& exit_code);
void add_slurm(CLI::App& app, int& exit_code);
void add_study(CLI::App& app, int& exit_code);

}  // namespace demcal::cli
