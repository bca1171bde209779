#include "common.hpp"

#include "db/sqlite.hpp"
#include "jobs/job_error.hpp"

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <optional>
#include <unistd.h>

namespace demcal::cli {

int guarded(const std::string& context, const std::function<int()>& body) {
  const std::string where = context.empty() ? "" : context + ": ";
  try {
    return body();
  } catch (const jobs::JobError& e) {
    // A command-line flag's fault is not the job file's: no file name before it.
    const bool flag = e.path().rfind("--", 0) == 0;
    std::cerr << "demcal: error: " << (e.path().empty() || flag ? "" : where) << e.what() << "\n";
    return kBadInput;
  } catch (const db::DbError& e) {
    std::cerr << "demcal: error: " << e.what() << "\n";
    return e.bad_input() ? kBadInput : kRuntime;
  } catch (const std::filesystem::filesystem_error& e) {
    // A path the user gave that cannot be a path here (a link loop, a name too long,
    // a file where a folder must be, no permission) is bad input; the rest (I/O
    // errors, a full disk) are runtime failures.
    const int code = e.code().value();
    const bool bad = code == ELOOP || code == ENAMETOOLONG || code == ENOTDIR || code == EACCES || code == EPERM ||
                     code == EEXIST || code == EISDIR;
    std::cerr << "demcal: error: cannot use " << (e.path1().empty() ? std::string("a path") : e.path1().string()) << ": "
              << e.code().message() << "\n";
    return bad ? kBadInput : kRuntime;
  } catch (const std::exception& e) {
    std::cerr << "demcal: error: " << e.what() << "\n";
    return kRuntime;
  }
}

int chosen_job_errors(bool job_given, const std::function<int()>& body) {
  if (job_given) return body();
  try {
    return body();
  } catch (const jobs::JobError& e) {
    if (e.path() != "--job") throw;
    throw jobs::JobError("", e.reason());
  }
}

namespace {

// Well-formed UTF-8 as RFC 3629 has it (what nlohmann::json accepts): no overlong
// forms, no surrogates (U+D800..DFFF), nothing past U+10FFFF.
bool valid_utf8(const std::string& s) {
  std::size_t i = 0;
  const std::size_t n = s.size();
  auto cont = [&](std::size_t k, unsigned lo = 0x80, unsigned hi = 0xBF) {
    if (k >= n) return false;
    const auto c = static_cast<unsigned char>(s[k]);
    return c >= lo && c <= hi;
  };
  while (i < n) {
    const auto c = static_cast<unsigned char>(s[i]);
    if (c < 0x80) {
      i += 1;
    } else if (c >= 0xC2 && c <= 0xDF) {
      if (!cont(i + 1)) return false;
      i += 2;
    } else if (c >= 0xE0 && c <= 0xEF) {
      const unsigned lo = c == 0xE0 ? 0xA0 : 0x80, hi = c == 0xED ? 0x9F : 0xBF;
      if (!cont(i + 1, lo, hi) || !cont(i + 2)) return false;
      i += 3;
    } else if (c >= 0xF0 && c <= 0xF4) {
      const unsigned lo = c == 0xF0 ? 0x90 : 0x80, hi = c == 0xF4 ? 0x8F : 0xBF;
      if (!cont(i + 1, lo, hi) || !cont(i + 2) || !cont(i + 3)) return false;
      i += 4;
    } else {
      return false;
    }
  }
  return true;
}


}  // namespace

std::string plain_path_error(const std::string& path) {
  if (path.empty()) return "empty path";
  for (const char ch : path)
    if (static_cast<unsigned char>(ch) < 0x20 || ch == 0x7f)
      return "the path contains a control character (newline, tab, ...): give a plain file name";
  if (!valid_utf8(path)) return "the path is not valid UTF-8";
  return "";
}

const CLI::Validator kPlainPath(plain_path_error, "PATH", "plain path");

const CLI::Validator kOneLine(
    [](std::string& text) {
      for (const char ch : text)
        if (static_cast<unsigned char>(ch) < 0x20 || ch == 0x7f)
          return std::string("contains a control character (newline, tab, ...): give one line of text");
      return valid_utf8(text) ? std::string() : std::string("is not valid UTF-8");
    },
    "", "one line of text");

const CLI::Validator kNonEmpty([](std::string& text) { return text.empty() ? std::string("must not be empty") : std::string(); },
                               "", "not empty");

const CLI::Validator kDbPath(
    [](std::string& path) {
      if (std::string e = plain_path_error(path); !e.empty()) return e;
      return db::sqlite_name_refusal(path);
    },
    "FILE", "database file");

namespace {
// The whole text as a finite number, else nullopt.
std::optional<double> finite_number(const std::string& text) {
  try {
    std::size_t used = 0;
    const double v = std::stod(text, &used);
    if (used == text.size() && std::isfinite(v)) return v;
  } catch (const std::exception&) {
  }
  return std::nullopt;
}
}  // namespace

const CLI::Validator kFinite(
    [](std::string& text) {
      return finite_number(text) ? std::string() : "must be a finite number, got \"" + text + "\"";
    },
    "NUMBER", "finite number");

// CLI11's PositiveNumber names its range with DBL_MAX written out in 309 digits.
const CLI::Validator kPositiveFinite(
    [](std::string& text) {
      const auto v = finite_number(text);
      return v && *v > 0 ? std::string() : "must be a positive finite number, got \"" + text + "\"";
    },
    "NUMBER > 0", "positive finite number");

namespace {
// [first, end of text) read as a decimal int64 by from_chars (no base prefix, no
// spaces, no '+'): `whole` when every character is a digit of it (or its '-').
struct DecimalInt {
  std::int64_t value = 0;
  bool whole = false, in_range = false;
};
DecimalInt read_decimal_int(const std::string& text, std::size_t first = 0) {
  DecimalInt d;
  const char* begin = text.data() + first;
  const auto [end, ec] = std::from_chars(begin, text.data() + text.size(), d.value);
  d.whole = end == text.data() + text.size() && end != begin;
  d.in_range = ec != std::errc::result_out_of_range;
  return d;
}
}  // namespace

// Whole text, no sign, within int64: CLI11 would clamp 99999999999999999999 to
// INT64_MAX and the error would name an id the user never typed. Attached with
// transform(), it hands CLI11 the id in plain decimal: CLI11 reads 010 as octal 8.
const CLI::Validator kTaskId(
    [](std::string& text) {
      const DecimalInt d = read_decimal_int(text);
      // v > 0 also refuses a '-'.
      const bool ok = d.whole && d.in_range && d.value > 0;
      if (ok) text = std::to_string(d.value);
      return ok ? std::string() : "must be a task id (a whole number from 1 to 9223372036854775807, the first column of demcal query), got \"" + text + "\"";
    },
    "ID", "task id");

const CLI::Validator kWholeNumber(
    [](std::string& text) {
      // A '+' the user typed is as good as none (from_chars takes only a '-').
      const DecimalInt d = read_decimal_int(text, text.size() > 1 && text[0] == '+' && text[1] != '-' ? 1 : 0);
      if (d.whole && !d.in_range) return "is out of range, got " + text;
      if (d.whole) text = std::to_string(d.value);
      return d.whole ? std::string() : "must be a whole number in decimal digits, got \"" + text + "\"";
    },
    "", "whole number");

std::string default_out_dir(const std::string& db_path) {
  const auto parent = std::filesystem::absolute(db_path).parent_path();
  return (parent / "demcal-out").string();
}

std::string out_flag(const std::string& out) {
  return out.empty() ? "--out (not given: the default, demcal-out/ next to --db)" : "--out";
}

void require_db(const std::string& db_path) {
  if (!std::filesystem::exists(db_path))
    throw jobs::JobError("--db", "no database at " + db_path + " (`demcal run JOB --db " + db_path + "` makes one; or give --db the path of an existing one)");
}

void require_writable_dir(const std::string& flag, const std::string& dir) {
  if (dir.empty()) throw jobs::JobError(flag, "empty path");
  // The nearest folder that exists must take new entries; nothing is created here.
  std::filesystem::path p = std::filesystem::absolute(dir);
  while (!std::filesystem::exists(p) && p.has_parent_path() && p.parent_path() != p) p = p.parent_path();
  if (!std::filesystem::is_directory(p)) throw jobs::JobError(flag, p.string() + " is not a folder (for " + dir + ")");
  if (::access(p.c_str(), W_OK) != 0) throw jobs::JobError(flag, "cannot write into the folder " + p.string() + " (for " + dir + ")");
}

void require_writable_file(const std::string& flag, const std::string& file) {
  if (file.empty()) throw jobs::JobError(flag, "empty path");
  const auto parent = std::filesystem::absolute(file).parent_path();
  if (!std::filesystem::is_directory(parent))
    throw jobs::JobError(flag, "the folder " + parent.string() + " does not exist (for " + file + ")");
  if (::access(parent.c_str(), W_OK) != 0)
    throw jobs::JobError(flag, "cannot write into the folder " + parent.string() + " (for " + file + ")");
  if (std::filesystem::is_directory(file)) throw jobs::JobError(flag, file + " is a folder, not a file");
  // access() says yes to root whatever the file system takes (/proc, a read-only
  // mount): a file made and removed there says what the writer will find.
  std::string probe = (parent / ".demcal-probe-XXXXXX").string();
  const int fd = ::mkstemp(probe.data());
  const int err = errno;
  if (fd < 0)
    throw jobs::JobError(flag, "cannot write into the folder " + parent.string() + " (for " + file + "): " +
                                   std::strerror(err));
  ::close(fd);
  ::unlink(probe.c_str());
}

void print_notes(const std::string& job_file, const std::vector<std::string>& notes) {
  for (const auto& n : notes) std::cerr << "demcal: note: " << job_file << ": " << n << "\n";
}

}  // namespace demcal::cli
