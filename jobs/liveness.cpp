#include "liveness.hpp"

#include "db/store.hpp"

#include <cmath>
#include <fstream>
#include <optional>
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

// A token's parts ("host:pid:start"); nullopt when it is not a token we wrote.
struct Token {
  std::string host, pid, start;
};
std::optional<Token> parse_token(const std::string& token) {
  const auto a = token.rfind(':');
  const auto b = a == std::string::npos || a == 0 ? std::string::npos : token.rfind(':', a - 1);
  if (b == std::string::npos) return std::nullopt;
  return Token{token.substr(0, b), token.substr(b + 1, a - b - 1), token.substr(a + 1)};
}

// A runner on this host: its process exists, is no zombie, and started when the
// token says (a recycled pid has another start time).
bool process_alive(const Token& t) {
  long pid = 0;
  try {
    pid = std::stol(t.pid);
  } catch (const std::exception&) {
    return false;
  }
  char state = 0;
  std::string start;
  if (!proc_stat(pid, state, start)) return false;
  if (state == 'Z' || state == 'X') return false;
  return start == t.start;
}

}  // namespace

std::string runner_token() {
  char state = 0;
  std::string start;
  proc_stat(static_cast<long>(getpid()), state, start);
  return host() + ":" + std::to_string(getpid()) + ":" + start;
}

bool holder_alive(db::Store& store, const std::string& token) {
  const auto t = parse_token(token);
  if (!t) return false;
  if (t->host == host()) return token == runner_token() || process_alive(*t);
  const auto seen = store.last_seen(token);
  return !seen || db::unix_now() - *seen < kRunnerLeaseS;
}

int requeue_dead_runners(db::Store& store) {
  return store.requeue_dead([&](const std::string& w) { return holder_alive(store, w); });
}

std::string describe_holder(db::Store& store, const std::string& token) {
  const auto t = parse_token(token);
  if (t && t->host == host()) return token + " (this host)";
  const auto seen = store.last_seen(token);
  if (!seen)
    return token + " (another host, no heartbeat: a demcal from before heartbeats; if it is gone, `demcal run JOB "
                   "--requeue-running` puts its tasks back)";
  const double ago = db::unix_now() - *seen;
  return token + " (another host, last seen " + std::to_string(static_cast<long>(std::lround(ago))) +
         " s ago; its tasks are re-queued once it is silent for " + std::to_string(static_cast<long>(kRunnerLeaseS)) + " s)";
}

Heartbeat::Heartbeat(db::Store& store, std::string token) : store_(store), token_(std::move(token)) {
  store_.beat(token_);
  last_ = std::chrono::steady_clock::now();
}

void Heartbeat::tick() {
  const auto now = std::chrono::steady_clock::now();
  if (now - last_ < std::chrono::duration<double>(kRunnerBeatS)) return;
  last_ = now;
  store_.beat(token_);
}

}  // namespace demcal::jobs
