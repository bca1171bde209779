#include "progress.hpp"

#include <cmath>
#include <cstdio>
#include <sstream>

namespace demcal::jobs {

std::string format_duration(double s) {
  if (!(s >= 0) || !std::isfinite(s)) return "--:--";
  char buf[32];
  if (s < 60) {
    std::snprintf(buf, sizeof buf, "%.1f s", s);
    return buf;
  }
  const long t = std::lround(s);
  if (t >= 3600)
    std::snprintf(buf, sizeof buf, "%ld:%02ld:%02ld", t / 3600, (t / 60) % 60, t % 60);
  else
    std::snprintf(buf, sizeof buf, "%ld:%02ld", t / 60, t % 60);
  return buf;
}

std::string plain_number(double v) {
  std::ostringstream o;
  o << v;
  return o.str();
}

Progress::Progress(std::ostream& err, bool terminal) : err_(err), terminal_(terminal) {}

void Progress::line(const std::string& text, const Counts& c) {
  if (terminal_ && bar_shown_) err_ << "\r\033[K";
  err_ << text << "  [" << (c.done + c.failed) << "/" << c.total << "]\n";
  if (terminal_) draw(c);
  err_.flush();
}

void Progress::update(const Counts& c, Eta eta) {
  eta_ = eta;
  if (!terminal_) return;
  const auto now = std::chrono::steady_clock::now();
  if (now - last_draw_ < std::chrono::milliseconds(200)) return;
  draw(c);
  err_.flush();
}

void Progress::draw(const Counts& c) {
  last_draw_ = std::chrono::steady_clock::now();
  const int width = 30;
  const int filled = c.total > 0 ? (c.done + c.failed) * width / c.total : width;
  std::string bar(static_cast<std::size_t>(filled), '#');
  bar.resize(static_cast<std::size_t>(width), ' ');
  err_ << "\r\033[K[" << bar << "] " << c.done << " done, " << c.failed << " failed, " << c.running << " running, "
       << (c.total - c.done - c.failed - c.running) << " queued  ETA "
       << (eta_.past_forecast ? std::string("past forecast")
                              : (eta_.at_most && eta_.s >= 0 ? "<= " : "") + format_duration(eta_.s))
       << (eta_.bound_s >= 0 && !eta_.at_most ? " (<= " + format_duration(eta_.bound_s) + ")" : "");
  bar_shown_ = true;
}

void Progress::finish() {
  if (terminal_ && bar_shown_) err_ << "\r\033[K";
  err_.flush();
  bar_shown_ = false;
}

}  // namespace demcal::jobs
