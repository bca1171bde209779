#pragma once
// Progress of a run on stderr: on a terminal a redrawn bar with done / failed /
// running counts and an ETA, plus one line per task state change; otherwise plain
// lines only (logs and CI stay readable).
#include <chrono>
#include <ostream>
#include <string>

namespace demcal::jobs {

struct Counts {
  int total = 0, done = 0, failed = 0, running = 0;
  // n more tasks of `status` ("pending", "running", "done", "failed").
  void add(const std::string& status, int n = 1) {
    total += n;
    if (status == "done") done += n;
    if (status == "failed") failed += n;
    if (status == "running") running += n;
  }
  // A running task ended as `status` ("pending" when it went back to the queue): the
  // tally a runner keeps between reads of the database.
  void ended(const std::string& status) {
    --running;
    if (status == "done") ++done;
    if (status == "failed") ++failed;
  }
};

// Seconds left (< 0: unknown); at_most: a bound (every task to its time limit), drawn
// "<="; past_forecast: the tasks still running have all run longer than forecast;
// bound_s (>= 0): a bound drawn beside an estimate.
struct Eta {
  double s = -1;
  bool at_most = false;
  bool past_forecast = false;
  double bound_s = -1;
};

class Progress {
 public:
  Progress(std::ostream& err, bool terminal);
  void line(const std::string& text, const Counts& c);  // a state change
  void update(const Counts& c, Eta eta);            // redraw the bar (terminal only)
  void set_eta(Eta eta) { eta_ = eta; }             // for the bar line() draws next
  void finish();

 private:
  void draw(const Counts& c);
  std::ostream& err_;
  bool terminal_;
  bool bar_shown_ = false;
  Eta eta_;
  std::chrono::steady_clock::time_point last_draw_{};
};

std::string format_duration(double seconds);
// A number as a stream writes it (6 significant digits, no trailing zeros): "0.5", "300".
std::string plain_number(double v);

}  // namespace demcal::jobs
