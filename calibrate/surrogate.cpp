#include "surrogate.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace demcal::calibrate {
namespace {

double tps(double r2) { return r2 > 0 ? 0.5 * r2 * std::log(r2) : 0.0; }  // r^2 log r

// Monomials u^i v^j with i + j <= degree.
int poly_terms(int degree) { return (degree + 1) * (degree + 2) / 2; }
void monomials(double u, double v, int degree, double* out) {
  int k = 0;
  for (int d = 0; d <= degree; ++d)
    for (int j = 0; j <= d; ++j) out[k++] = std::pow(u, d - j) * std::pow(v, j);
}

struct Trial {
  double loo_rms = INFINITY, loo_max = 0;
  double leverage = 1;  // mean diagonal of the hat matrix: effective parameters / points
  Eigen::VectorXd w, poly;
  Eigen::MatrixXd coef_map;  // coefficients = coef_map * y
};

// Thin-plate spline with a linear polynomial; the smoothing term lambda / weight_i on
// the diagonal lets noisier points (fewer replicas) be followed less closely.
// LOO residuals from Rippa's formula e_i = c_i / (A^-1)_ii, exact for this system.
Trial thin_plate(const std::vector<double>& u, const std::vector<double>& v, const Eigen::VectorXd& y,
                 const Eigen::VectorXd& wt, double lambda) {
  const int n = static_cast<int>(u.size());
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(n + 3, n + 3);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      const double du = u[i] - u[j], dv = v[i] - v[j];
      A(i, j) = tps(du * du + dv * dv);
    }
    A(i, i) += lambda / wt(i);
    A(i, n) = A(n, i) = 1;
    A(i, n + 1) = A(n + 1, i) = u[i];
    A(i, n + 2) = A(n + 2, i) = v[i];
  }
  Trial t;
  Eigen::FullPivLU<Eigen::MatrixXd> lu(A);
  if (!lu.isInvertible()) return t;
  const Eigen::MatrixXd inv = lu.inverse();
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(n + 3);
  rhs.head(n) = y;
  const Eigen::VectorXd c = inv * rhs;
  if (!c.allFinite()) return t;
  double ss = 0, mx = 0, h = 0;
  for (int i = 0; i < n; ++i) {
    const double e = c(i) / inv(i, i);
    ss += e * e;
    mx = std::max(mx, std::abs(e));
    h += 1.0 - lambda / wt(i) * inv(i, i);  // s(x_i) = y_i - (lambda / w_i) c_i
  }
  t.loo_rms = std::sqrt(ss / n);
  t.leverage = h / n;
  t.loo_max = mx;
  t.w = c.head(n);
  t.poly = c.tail(3);
  t.coef_map = inv.leftCols(n);
  return t;
}

// Weighted least-squares polynomial; LOO residuals r_i / (1 - h_ii).
Trial polynomial(const std::vector<double>& u, const std::vector<double>& v, const Eigen::VectorXd& y,
                 const Eigen::VectorXd& wt, int degree) {
  const int n = static_cast<int>(u.size()), m = poly_terms(degree);
  Trial t;
  if (n < m + 2) return t;
  Eigen::MatrixXd X(n, m);
  for (int i = 0; i < n; ++i) {
    std::vector<double> row(static_cast<std::size_t>(m));
    monomials(u[i], v[i], degree, row.data());
    for (int k = 0; k < m; ++k) X(i, k) = row[static_cast<std::size_t>(k)];
  }
  const Eigen::VectorXd sw = wt.cwiseSqrt();
  const Eigen::MatrixXd Xw = sw.asDiagonal() * X;
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(Xw);
  if (qr.rank() < m) return t;  // e.g. only two theta values: u^2 is not identifiable
  const Eigen::VectorXd beta = qr.solve(sw.cwiseProduct(y));
  const Eigen::MatrixXd G = (Xw.transpose() * Xw).inverse();
  double ss = 0, mx = 0, hsum = 0;
  for (int i = 0; i < n; ++i) {
    const double h = wt(i) * X.row(i).dot(G * X.row(i).transpose());
    hsum += h;
    const double r = y(i) - X.row(i).dot(beta);
    if (1 - h < 1e-10) return Trial{};
    const double e = r / (1 - h);
    ss += e * e;
    mx = std::max(mx, std::abs(e));
  }
  t.loo_rms = std::sqrt(ss / n);
  t.loo_max = mx;
  t.leverage = hsum / n;
  t.poly = beta;
  t.coef_map = G * X.transpose() * wt.asDiagonal();  // beta = (X'WX)^-1 X'W y
  return t;
}

}  // namespace

std::string kind_name(SurrogateKind k) {
  switch (k) {
    case SurrogateKind::thin_plate: return "thin-plate spline";
    case SurrogateKind::quadratic: return "quadratic polynomial";
    case SurrogateKind::cubic: return "cubic polynomial";
  }
  return "?";
}

double Surrogate::operator()(double theta, double eta) const {
  const double uu = u(theta), vv = v(eta);
  if (kind_ == SurrogateKind::thin_plate) {
    double s = poly_(0) + poly_(1) * uu + poly_(2) * vv;
    for (std::size_t i = 0; i < u_.size(); ++i) {
      const double du = uu - u_[i], dv = vv - v_[i];
      s += w_(static_cast<Eigen::Index>(i)) * tps(du * du + dv * dv);
    }
    return s;
  }
  const int degree = kind_ == SurrogateKind::quadratic ? 2 : 3;
  double row[10];
  monomials(uu, vv, degree, row);
  double s = 0;
  for (int k = 0; k < poly_terms(degree); ++k) s += poly_(k) * row[k];
  return s;
}

Eigen::VectorXd Surrogate::hat(double theta, double eta) const {
  const double uu = u(theta), vv = v(eta);
  if (kind_ == SurrogateKind::thin_plate) {
    const auto n = static_cast<Eigen::Index>(u_.size());
    Eigen::VectorXd basis(n + 3);
    for (Eigen::Index i = 0; i < n; ++i) {
      const double du = uu - u_[static_cast<std::size_t>(i)], dv = vv - v_[static_cast<std::size_t>(i)];
      basis(i) = tps(du * du + dv * dv);
    }
    basis.tail(3) << 1.0, uu, vv;
    return coef_map_.transpose() * basis;
  }
  const int degree = kind_ == SurrogateKind::quadratic ? 2 : 3;
  Eigen::VectorXd basis(poly_terms(degree));
  monomials(uu, vv, degree, basis.data());
  return coef_map_.transpose() * basis;
}

std::string Surrogate::describe(const std::string& unit) const {
  char b[200];
  const std::string u = unit.empty() ? "" : " " + unit;
  if (kind_ == SurrogateKind::thin_plate)
    std::snprintf(b, sizeof b, "%s (smoothing %.3g), LOO RMS %.3g%s over %d points", kind_name(kind_).c_str(), lambda_,
                  loo_rms_, u.c_str(), points());
  else
    std::snprintf(b, sizeof b, "%s, LOO RMS %.3g%s over %d points", kind_name(kind_).c_str(), loo_rms_, u.c_str(),
                  points());
  return b;
}

Surrogate fit_surrogate(const std::vector<double>& theta, const std::vector<double>& eta, const std::vector<double>& y,
                        const std::vector<double>& weight, const Box& box) {
  const std::size_t n = theta.size();
  if (n < 4) throw std::invalid_argument("a surface over (theta, eta) needs at least 4 points with data, got " + std::to_string(n));
  if (!(box.theta_hi > box.theta_lo) || !(box.eta_hi > box.eta_lo))
    throw std::invalid_argument("a surface over (theta, eta) needs at least two values of each");
  Surrogate s;
  s.box_ = box;
  for (std::size_t i = 0; i < n; ++i) {
    s.u_.push_back(s.u(theta[i]));
    s.v_.push_back(s.v(eta[i]));
  }
  Eigen::VectorXd Y(static_cast<Eigen::Index>(n)), W(static_cast<Eigen::Index>(n));
  double wmean = 0;
  for (std::size_t i = 0; i < n; ++i) wmean += std::max(1.0, weight[i]);
  wmean /= static_cast<double>(n);
  for (std::size_t i = 0; i < n; ++i) {
    Y(static_cast<Eigen::Index>(i)) = y[i];
    W(static_cast<Eigen::Index>(i)) = std::max(1.0, weight[i]) / wmean;
  }
  // Not all on one line: the linear part must be identifiable.
  Eigen::MatrixXd L(static_cast<Eigen::Index>(n), 3);
  for (std::size_t i = 0; i < n; ++i) L.row(static_cast<Eigen::Index>(i)) << 1, s.u_[i], s.v_[i];
  if (Eigen::ColPivHouseholderQR<Eigen::MatrixXd>(L).rank() < 3)
    throw std::invalid_argument("the points lie on one line in (theta, eta); a surface needs a spread in both");

  Trial best;
  SurrogateCandidate best_c{SurrogateKind::thin_plate, 0, INFINITY};
  auto consider = [&](SurrogateKind k, double lambda, Trial t) {
    if (!std::isfinite(t.loo_rms)) return;
    s.candidates_.push_back({k, lambda, t.loo_rms});
    if (t.loo_rms < best_c.loo_rms) {
      best_c = {k, lambda, t.loo_rms};
      best = std::move(t);
    }
  };
  consider(SurrogateKind::thin_plate, 0.0, thin_plate(s.u_, s.v_, Y, W, 0.0));
  for (double e = -7; e <= 1.0001; e += 0.25) {
    const double lambda = std::pow(10.0, e);
    consider(SurrogateKind::thin_plate, lambda, thin_plate(s.u_, s.v_, Y, W, lambda));
  }
  consider(SurrogateKind::quadratic, 0, polynomial(s.u_, s.v_, Y, W, 2));
  consider(SurrogateKind::cubic, 0, polynomial(s.u_, s.v_, Y, W, 3));
  if (!std::isfinite(best_c.loo_rms)) throw std::invalid_argument("no surrogate could be fitted to these points");
  s.kind_ = best_c.kind;
  s.lambda_ = best_c.lambda;
  s.loo_rms_ = best.loo_rms;
  s.loo_max_ = best.loo_max;
  s.leverage_ = best.leverage;
  s.w_ = best.w;
  s.poly_ = best.poly;
  s.coef_map_ = best.coef_map;
  return s;
}

Surrogate fit_surrogate(const ResponseSurface& rs) {
  std::vector<double> th, et, y, w;
  for (const auto& p : rs.points)
    if (!p.hole()) {
      th.push_back(p.theta);
      et.push_back(p.eta);
      y.push_back(p.mean);
      w.push_back(p.n());
    }
  try {
    return fit_surrogate(th, et, y, w, rs.box());
  } catch (const std::invalid_argument& e) {
    if (th.size() >= 4) throw;  // another refusal: the points' count is not its reason
    // Too few points: say why the other grid points have no value, as the count
    // alone hides that most tasks failed.
    GridPoint why;
    int holes = 0;
    for (const auto& p : rs.points)
      if (p.hole() && !p.refine) {
        ++holes;
        why.failed += p.failed;
        why.invalid += p.invalid;
        why.unfinished += p.unfinished;
        why.missing += p.missing;
      }
    if (holes == 0) throw;
    const std::string tasks = why.without_value();
    throw std::invalid_argument(std::string(e.what()) + " (" + std::to_string(holes) + " grid point(s) have no data: " +
                                (tasks.empty() ? std::string("no task there") : "their tasks " + tasks) +
                                (why.failed > 0 ? std::string("; demcal status shows why tasks failed") : std::string()) +
                                ")");
  }
}

}  // namespace demcal::calibrate
