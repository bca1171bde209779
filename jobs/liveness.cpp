#include "liveness.hpp"

#include "db/store.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <optional>
#include <ostream>
#include <sstream>
#include <unistd.h>
#include <vector>

namespace demcal::jobs {

std::string hostname() {
  char buf[256] = {};
  gethostname(buf, sizeof buf - 1);
  return buf;
}

namespace {

// "This host" is this hostname and this pid namespace: runners in two containers
// that share a hostname cannot see each other's processes, and judged by pid each
// took the other for dead and re-queued its tasks over and over (one task ran 22
// times). Across namespaces they are judged by heartbeat, as across hosts.
std::string host() {
  std::string h = hostname();
  char link[64] = {};
  const ssize_t n = readlink("/proc/self/ns/pid", link, sizeof link - 1);
  const std::string ns(link, n > 0 ? static_cast<std::size_t>(n) : 0);  // "pid:[4026531836]"
  const auto a = ns.find('['), b = ns.find(']');
  if (a != std::string::npos && b != std::string::npos && b > a + 1) h += "/pidns" + ns.substr(a + 1, b - a - 1);
  return h;
}

// A token written by a demcal from before the namespace was part of "this host"
// names the bare hostname: judged by its process as before.
bool on_this_host(const std::string& token_host) { return token_host == host() || token_host == hostname(); }

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

std::string process_host_tag() {
  std::string tag = host();
  std::replace(tag.begin(), tag.end(), '/', '-');
  return tag;
}

bool process_alive_here(long pid) {
  char state = 0;
  std::string start;
  return proc_stat(pid, state, start) && state != 'Z' && state != 'X';
}

std::string runner_token() {
  char state = 0;
  std::string start;
  proc_stat(static_cast<long>(getpid()), state, start);
  return host() + ":" + std::to_string(getpid()) + ":" + start;
}

bool BeatWatch::alive(const std::string& token, std::optional<double> last_seen, double unix_now, double watch_s) {
  if (!last_seen) return true;
  const auto [it, first_sight] = seen_.try_emplace(token, Seen{*last_seen, watch_s, std::nullopt});
  if (!first_sight && it->second.stamp != *last_seen) it->second = Seen{*last_seen, watch_s, unix_now - *last_seen};
  const double unchanged_for = watch_s - it->second.since;
  if (unchanged_for >= kRunnerLeaseS) return false;
  if (unix_now - *last_seen < kRunnerLeaseS) return true;
  return unchanged_for < kRunnerConfirmS;
}

std::optional<double> BeatWatch::clock_behind(const std::string& token) const {
  const auto it = seen_.find(token);
  if (it == seen_.end() || !it->second.behind || *it->second.behind < 2 * kRunnerBeatS) return std::nullopt;
  return it->second.behind;
}

namespace {
double watch_clock_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}
std::string seconds(double s) { return std::to_string(static_cast<long>(std::lround(s))) + " s"; }
}  // namespace

namespace {
// A runner on this host: alive by its process (this one, or another still running).
bool alive_here(const std::string& token, const Token& t) { return token == runner_token() || process_alive(t); }
}  // namespace

bool holder_alive(db::Store& store, const std::string& token, BeatWatch* watch) {
  const auto t = parse_token(token);
  if (!t) return false;
  if (on_this_host(t->host)) return alive_here(token, *t);
  const auto seen = store.last_seen(token);
  if (watch) return watch->alive(token, seen, db::unix_now(), watch_clock_s());
  return !seen || db::unix_now() - *seen < kRunnerLeaseS;
}

int requeue_dead_runners(db::Store& store, BeatWatch* watch) {
  return store.requeue_dead([&](const std::string& w) { return holder_alive(store, w, watch); });
}

int requeue_running_tasks(db::Store& store, std::int64_t job_id, std::ostream& log) {
  std::vector<std::string> live;
  const int n = store.requeue_running(job_id, [&](const std::string& w) {
    const auto t = parse_token(w);
    const bool keep = t && on_this_host(t->host) && alive_here(w, *t);
    if (keep) live.push_back(w);
    return keep;
  });
  if (n > 0) log << "re-queued " << n << " running task(s) (--requeue-running)\n";
  for (const auto& w : live)
    log << "--requeue-running: left the tasks of " << w << " running: that runner is alive on this host and would go on "
        << "running them; stop it first\n";
  return n;
}

std::string describe_holder(db::Store& store, const std::string& token, const BeatWatch* watch) {
  const auto t = parse_token(token);
  if (t && on_this_host(t->host)) return token + " (this host)";
  const auto seen = store.last_seen(token);
  if (!seen)
    return token + " (another host, no heartbeat: a demcal from before heartbeats; if it is gone, `demcal run JOB "
                   "--requeue-running` puts its tasks back)";
  if (const auto behind = watch ? watch->clock_behind(token) : std::nullopt)
    return token + " (another host, beating, with its clock about " + seconds(*behind) +
           " behind this host's; its tasks are re-queued once it is silent for " + seconds(kRunnerLeaseS) + ")";
  const double ago = db::unix_now() - *seen;
  if (ago < -kRunnerBeatS)
    return token + " (another host, its last beat stamped " + seconds(-ago) +
           " ahead of this host's clock; its tasks are re-queued once it is silent for " + seconds(kRunnerLeaseS) + ")";
  if (watch && ago >= kRunnerLeaseS)
    return token + " (another host, last seen " + seconds(ago) + " ago by its own clock; its tasks are re-queued unless a "
                   "beat arrives within " + seconds(kRunnerConfirmS) + ": a host's clock may run behind this one's)";
  return token + " (another host, last seen " + seconds(std::max(0.0, ago)) + " ago; its tasks are re-queued once it is silent for " +
         seconds(kRunnerLeaseS) + ")";
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
