#include "liveness.hpp"

#include <fstream>
#include <sstream>
#include <unistd.h>

namespace demcal::jobs {
namespace {

std::string host() {
  char buf[256] = {};
  gethostname(buf, sizeof buf - 1);
  return buf;
}

// State letter and start time (field 22) of a process, or empty when none.
bool proc_stat(long pid, char& state, std::string& start) {
  std::ifstream f("/proc/" + std::to_string(pid) + "/stat");
  std::string line;
  if (!f || !std::getline(f, line)) return false;
  const auto close = line.rfind(')');  // the command name may contain spaces
  if (close == std::string::npos) return false;
  std::istringstream rest(line.substr(close + 1));
  std::string field;
  rest >> state;
  for (int i = 4; i <= 22 && rest >> field; ++i) {
  }
  start = field;
  return true;
}

}  // namespace

std::string runner_token() {
  char state = 0;
  std::string start;
  proc_stat(static_cast<long>(getpid()), state, start);
  return host() + ":" + std::to_string(getpid()) + ":" + start;
}

bool runner_alive(const std::string& token) {
  const auto a = token.rfind(':');
  const auto b = a == std::string::npos || a == 0 ? std::string::npos : token.rfind(':', a - 1);
  if (b == std::string::npos) return false;  // not a token we wrote
  if (token.substr(0, b) != host()) return true;
  if (token == runner_token()) return true;
  long pid = 0;
  try {
    pid = std::stol(token.substr(b + 1, a - b - 1));
  } catch (const std::exception&) {
    return false;
  }
  char state = 0;
  std::string start;
  if (!proc_stat(pid, state, start)) return false;
  if (state == 'Z' || state == 'X') return false;
  return start == token.substr(a + 1);
}

}  // namespace demcal::jobs
