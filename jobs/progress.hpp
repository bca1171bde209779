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
};

class Progress {
 public:
  Progress(std::ostream& err, bool terminal);
  void line(const std::string& text, const Counts& c);  // a state change
  void update(const Counts& c, double eta_s);            // redraw the bar (terminal only)
  void set_eta(double eta_s) { eta_s_ = eta_s; }         // for the bar line() draws next
  void finish();

 private:
  void draw(const Counts& c);
  std::ostream& err_;
  bool terminal_;
  bool bar_shown_ = false;
  double eta_s_ = -1;
  std::chrono::steady_clock::time_point last_draw_{};
};

std::string format_duration(double seconds);

}  // namespace demcal::jobs
