#include "leftover_files.hpp"

#include "liveness.hpp"
#include "runner.hpp"

#include "db/store.hpp"

#include <cctype>
#include <map>
#include <system_error>

namespace demcal::jobs {
namespace {

bool ends_with(const std::string& s, const std::string& tail) {
  return s.size() >= tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
}

bool all_digits(const std::string& s) {
  if (s.empty()) return false;
  for (char c : s)
    if (!std::isdigit(static_cast<unsigned char>(c))) return false;
  return true;
}

// ".task-ID.TAG.result.json" or its ".tmp": TAG, else "". An MPI worker rank's file,
// ".task-ID.TAG.rankN.result.json", is its farm's: TAG is rank 0's, the runner whose
// death orphans it.
std::string result_file_tag(const std::string& name) {
  static const std::string head = ".task-";
  std::string rest;
  for (const std::string tail : {".result.json", ".result.json.tmp"})
    if (ends_with(name, tail)) rest = name.substr(0, name.size() - tail.size());
  if (rest.compare(0, head.size(), head) != 0) return "";
  const auto dot = rest.find('.', head.size());
  if (dot == std::string::npos || !all_digits(rest.substr(head.size(), dot - head.size()))) return "";
  std::string tag = rest.substr(dot + 1);
  const auto rank = tag.rfind(".rank");
  if (rank != std::string::npos && all_digits(tag.substr(rank + 5))) tag.erase(rank);
  return tag;
}

// "NAME.HOST-PID.part" written in this host's pid namespace (HOST is
// process_host_tag()): PID, else "" (another namespace's pids are not ours to judge).
std::string part_file_pid(const std::string& name) {
  const std::string mid = "." + process_host_tag() + "-";
  if (!ends_with(name, ".part")) return "";
  const std::string stem = name.substr(0, name.size() - 5);
  const auto at = stem.rfind(mid);
  if (at == std::string::npos) return "";
  const std::string pid = stem.substr(at + mid.size());
  return all_digits(pid) ? pid : "";
}

}  // namespace

std::string leftovers_removed_line(int n, const std::filesystem::path& dir) {
  return "removed " + std::to_string(n) + " partial file(s) left in " + dir.string() + "/ by runners that are gone";
}

int remove_leftovers_of_dead_runners(const std::filesystem::path& dir, db::Store& store, const std::string& own_tag,
                                     BeatWatch* watch) {
  std::map<std::string, std::string> token_of_tag;
  for (const auto& token : store.runner_tokens()) token_of_tag.emplace(file_name_safe(token), token);
  std::error_code ec;
  std::filesystem::directory_iterator it(dir, ec), end;
  int removed = 0;
  for (; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    bool dead = false;
    if (const std::string tag = result_file_tag(name); !tag.empty()) {
      const auto t = token_of_tag.find(tag);
      dead = tag != own_tag && t != token_of_tag.end() && !holder_alive(store, t->second, watch);
    } else if (const std::string pid = part_file_pid(name); !pid.empty()) {
      // The worker that wrote it, a child of its runner, dies with it (PDEATHSIG); a
      // zombie until reaped, which may be after the next run starts. (Ten digits and
      // more is no pid of ours, and could overflow stol.)
      dead = pid.size() < 10 && !process_alive_here(std::stol(pid));
    }
    std::error_code rm;
    if (dead && std::filesystem::is_regular_file(it->path(), rm) && std::filesystem::remove(it->path(), rm)) ++removed;
  }
  return removed;
}

}  // namespace demcal::jobs
