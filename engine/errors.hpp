#pragma once
// Exceptions the engine raises. A scene catches them and reports a failed result;
// none is ever swallowed into a silently wrong metric.
#include <stdexcept>
#include <string>

namespace demcal::engine {

// A config field is missing, non-finite or out of range. `field` names it.
class ConfigError : public std::invalid_argument {
 public:
  ConfigError(std::string field, std::string reason)
      : std::invalid_argument(field + ": " + reason), field_(std::move(field)), reason_(std::move(reason)) {}
  const std::string& field() const { return field_; }
  // Without the field: for a caller that re-raises it under a key of its own.
  const std::string& reason() const { return reason_; }

 private:
  std::string field_, reason_;
};

// The requested time step exceeds the stability limit of a mode of the contact law.
class TimestepError : public std::invalid_argument {
 public:
  TimestepError(std::string mode, double dt, double limit, const std::string& what)
      : std::invalid_argument(what), mode_(std::move(mode)), dt_(dt), limit_(limit) {}
  const std::string& mode() const { return mode_; }
  double dt() const { return dt_; }
  double limit() const { return limit_; }

 private:
  std::string mode_;
  double dt_, limit_;
};

// The integration went unstable: non-finite state, excessive overlap or energy
// created where none can be. Carries the step, the particle and the quantity.
class InstabilityError : public std::runtime_error {
 public:
  InstabilityError(long step, long particle, std::string quantity, const std::string& what)
      : std::runtime_error(what), step_(step), particle_(particle), quantity_(std::move(quantity)) {}
  long step() const { return step_; }
  long particle() const { return particle_; }
  const std::string& quantity() const { return quantity_; }

 private:
  long step_;
  long particle_;
  std::string quantity_;
};

}  // namespace demcal::engine
