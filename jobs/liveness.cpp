#include "liveness.hpp"

#include "db/store.hpp"

#include <chrono>
#include <cmath>

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

std::string host_of(const std::string& token) {
  const auto a = token.rfind(':');
  const auto b = a == std::string::npos || a == 0 ? std::string::npos : token.rfind(':', a - 1);
  return b == std::string::npos ? std::string() : token.substr(0, b);
}

double now_s() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

}  // namespace

bool holder_alive(db::Store& store, const std::string& token) {
  if (host_of(token) == host() || host_of(token).empty()) return runner_alive(token);
  const auto seen = store.last_seen(token);
  return !seen || now_s() - *seen < kRunnerLeaseS;
}

int requeue_dead_runners(db::Store& store) {
  return store.requeue_dead([&](const std::string& w) { return holder_alive(store, w); });
}

std::string describe_holder(db::Store& store, const std::string& token) {
  if (host_of(token) == host()) return token + " (this host)";
  const auto seen = store.last_seen(token);
  if (!seen)
    return token + " (another host, no heartbeat: a demcal from before heartbeats; if it is gone, `demcal run JOB "
                   "--requeue-running` puts its tasks back)";
  const double ago = now_s() - *seen;
  return token + " (another host, last seen " + std::to_string(static_cast<long>(std::lround(ago))) +
         " s ago; its tasks are re-queued once it is silent for " + std::to_string(static_cast<long>(kRunnerLeaseS)) + " s)";
}

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
