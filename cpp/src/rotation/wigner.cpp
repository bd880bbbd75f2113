#include <spectral_vs/rotation/so3.hpp>
#include <spectral_vs/rotation/wigner.hpp>

#include <Eigen/Geometry>

#include "common/checks.hpp"
#include "rotation/harmonics_detail.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <mutex>
#include <vector>

namespace spectral_vs {

using detail::fail;

namespace {

// One term of the Ivanic-Ruedenberg recursion for row m of U^l: coef * P(i, a, n), where
// P(i, a, n) combines row i of U^1 (i = -1, 0, 1) with row a of U^{l-1}. Every row has at
// most five terms (one from u, two from v, two from w); unused slots have coef 0.
struct Term {
  int i = 0;  // -1, 0, 1
  int a = 0;  // row of U^{l-1}, -(l-1)..l-1
  double coef = 0.0;
};
using RowTerms = std::array<Term, 5>;

struct DegreeRecursion {
  std::vector<RowTerms> rows;   // [m + l]
  std::vector<double> inv_den;  // [n + l]: the column factor of u, v, w
};

// The coefficients u, v, w of the erratum (1998) with their column factor split off:
// u = sqrt((l+m)(l-m)) / d(n), v = 1/2 sqrt((1+delta_m0)(l+|m|-1)(l+|m|)) (1 - 2 delta_m0) / d(n),
// w = -1/2 sqrt((l-|m|-1)(l-|m|)) (1 - delta_m0) / d(n), d(n) = sqrt((l+n)(l-n)) or
// sqrt(2l(2l-1)) when |n| = l. The sqrt(1 + delta) factors of V are folded in.
DegreeRecursion build_recursion(int l) {
  DegreeRecursion r;
  r.rows.resize(2 * l + 1);
  r.inv_den.resize(2 * l + 1);
  for (int n = -l; n <= l; ++n) {
    const double den = std::abs(n) == l ? 2.0 * l * (2.0 * l - 1.0) : double(l + n) * (l - n);
    r.inv_den[n + l] = 1.0 / std::sqrt(den);
  }
  for (int m = -l; m <= l; ++m) {
    const int am = std::abs(m);
    const double d = m == 0 ? 1.0 : 0.0;
    const double u = std::sqrt(double(l + m) * (l - m));
    const double v = 0.5 * std::sqrt((1.0 + d) * (l + am - 1.0) * (l + am)) * (1.0 - 2.0 * d);
    const double w = -0.5 * std::sqrt(std::max(0.0, (l - am - 1.0) * (l - am))) * (1.0 - d);
    RowTerms terms{};
    int t = 0;
    auto add = [&](int i, int a, double coef) { terms[t++] = Term{i, a, coef}; };
    if (am < l) add(0, m, u);
    if (m == 0) {
      add(1, 1, v);
      add(-1, -1, v);
    } else if (m > 0) {
      add(1, m - 1, m == 1 ? M_SQRT2 * v : v);
      if (m != 1) add(-1, -m + 1, -v);
    } else {
      if (m != -1) add(1, m + 1, v);
      add(-1, -m - 1, m == -1 ? M_SQRT2 * v : v);
    }
    if (m != 0 && am <= l - 2) {
      if (m > 0) {
        add(1, m + 1, w);
        add(-1, -m - 1, w);
      } else {
        add(1, m - 1, w);
        add(-1, -m + 1, -w);
      }
    }
    r.rows[m + l] = terms;
  }
  return r;
}

// Built once per degree, on first use, for the whole process.
const DegreeRecursion& recursion(int l) {
  static std::array<std::once_flag, detail::kMaxDegree + 1> once;
  static std::array<DegreeRecursion, detail::kMaxDegree + 1> table;
  std::call_once(once[l], [l] { table[l] = build_recursion(l); });
  return table[l];
}

// Interior columns |n| < l of U^l, where P(i, a, n) = R1(i, 0) prev(a, n): the weights
// coef * R1(i, 0) depend on the row only, so they are folded once per degree and each
// entry is five multiply-adds on one contiguous column of U^{l-1}.
void interior_columns(const DegreeRecursion& rec, const Eigen::Matrix3d& R1,
                      const Eigen::MatrixXd& prev, int l, Eigen::MatrixXd& out) {
  const int size = 2 * l + 1, lp = l - 1;
  thread_local std::vector<std::array<double, 5>> weight;
  thread_local std::vector<std::array<int, 5>> row;
  weight.resize(size);
  row.resize(size);
  for (int r = 0; r < size; ++r) {
    for (int t = 0; t < 5; ++t) {
      const Term& term = rec.rows[r][t];
      weight[r][t] = term.coef * R1(term.i + 1, 1);
      row[r][t] = term.a + lp;
    }
  }
  for (int n = -l + 1; n <= l - 1; ++n) {
    const double* x = prev.col(n + lp).data();
    double* y = out.col(n + l).data();
    const double scale = rec.inv_den[n + l];
    for (int r = 0; r < size; ++r) {
      const auto& wr = weight[r];
      const auto& ar = row[r];
      y[r] = scale * (wr[0] * x[ar[0]] + wr[1] * x[ar[1]] + wr[2] * x[ar[2]] + wr[3] * x[ar[3]] +
                      wr[4] * x[ar[4]]);
    }
  }
}

// Edge columns n = +-l mix the first and last columns of U^{l-1}:
// P(i, a, l) = R1(i, 1) prev(a, l-1) - R1(i, -1) prev(a, -l+1),
// P(i, a, -l) = R1(i, 1) prev(a, -l+1) + R1(i, -1) prev(a, l-1).
void edge_columns(const DegreeRecursion& rec, const Eigen::Matrix3d& R1,
                  const Eigen::MatrixXd& prev, int l, Eigen::MatrixXd& out) {
  const int size = 2 * l + 1, lp = l - 1;
  const auto first = prev.col(0), last = prev.col(2 * lp);
  thread_local Eigen::Matrix<double, Eigen::Dynamic, 3> c;
  c.resize(2 * lp + 1, 3);
  for (const int n : {-l, l}) {
    for (int i = -1; i <= 1; ++i) {
      const double p = R1(i + 1, 2), q = R1(i + 1, 0);
      if (n == l) {
        c.col(i + 1) = p * last - q * first;
      } else {
        c.col(i + 1) = p * first + q * last;
      }
    }
    const double scale = rec.inv_den[n + l];
    for (int r = 0; r < size; ++r) {
      double sum = 0.0;
      for (const Term& term : rec.rows[r]) sum += term.coef * c(term.a + lp, term.i + 1);
      out(r, n + l) = scale * sum;
    }
  }
}

// U^l from U^1 (R1) and U^{l-1} (prev), column by column (the storage order).
void next_degree(const Eigen::Matrix3d& R1, const Eigen::MatrixXd& prev, int l,
                 Eigen::MatrixXd& out) {
  const DegreeRecursion& rec = recursion(l);
  out.resize(2 * l + 1, 2 * l + 1);
  interior_columns(rec, R1, prev, l, out);
  edge_columns(rec, R1, prev, l, out);
}

// Calls visit(row, column, value) for the non-zeros of u^l(e_axis), indices m + l.
// Derived from the angular momentum operators in this real basis; checked against
// finite differences of wigner_real in the tests.
template <typename Visit>
void for_each_generator_entry(int l, int axis, Visit&& visit) {
  if (axis == 2) {  // z: rotates each (cos m phi, sin m phi) pair at rate m
    for (int m = 1; m <= l; ++m) {
      visit(l - m, l + m, double(m));
      visit(l + m, l - m, -double(m));
    }
    return;
  }
  const double s = std::sqrt(0.5 * l * (l + 1.0));
  if (axis == 1) {  // y: couples m with m + 1 within the cosine and within the sine terms
    if (l >= 1) {
      visit(l, l + 1, -s);
      visit(l + 1, l, s);
    }
    for (int m = 1; m < l; ++m) {
      const double c = 0.5 * std::sqrt(double(l - m) * (l + m + 1));
      visit(l + m, l + m + 1, -c);
      visit(l + m + 1, l + m, c);
      visit(l - m - 1, l - m, c);
      visit(l - m, l - m - 1, -c);
    }
    return;
  }
  // x: couples the cosine terms of order m with the sine terms of order m + 1
  if (l >= 1) {
    visit(l - 1, l, -s);
    visit(l, l - 1, s);
  }
  for (int m = 1; m < l; ++m) {
    const double c = 0.5 * std::sqrt(double(l - m) * (l + m + 1));
    visit(l - m, l + m + 1, -c);
    visit(l + m + 1, l - m, c);
    visit(l - m - 1, l + m, -c);
    visit(l + m, l - m - 1, c);
  }
}

WignerGenerators build_generators(int lmax) {
  WignerGenerators g;
  for (int axis = 0; axis < 3; ++axis) {
    auto& list = axis == 0 ? g.x : axis == 1 ? g.y : g.z;
    list.resize(lmax + 1);
    for (int l = 0; l <= lmax; ++l) {
      list[l] = Eigen::MatrixXd::Zero(2 * l + 1, 2 * l + 1);
      for_each_generator_entry(l, axis, [&](int r, int c, double v) { list[l](r, c) = v; });
    }
  }
  return g;
}

}  // namespace

void wigner_real_into(const Eigen::Matrix3d& R, int lmax, WignerMatrices& out) {
  require_rotation(R, "R");
  detail::require_degree(lmax, "lmax");
  out.resize(lmax + 1);
  out[0].setOnes(1, 1);
  if (lmax == 0) return;
  // U^1: R with rows and columns in the order (y, z, x) of S^1_{-1}, S^1_0, S^1_1.
  static constexpr int order[3] = {1, 2, 0};
  Eigen::Matrix3d R1;
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) R1(a, b) = R(order[a], order[b]);
  out[1] = R1;
  for (int l = 2; l <= lmax; ++l) next_degree(R1, out[l - 1], l, out[l]);
}

WignerMatrices wigner_real(const Eigen::Matrix3d& R, int lmax) {
  WignerMatrices out;
  wigner_real_into(R, lmax, out);
  return out;
}

WignerPullback::WignerPullback(int lmax) : lmax_(lmax) {
  detail::require_degree(lmax, "lmax");
  wigner_real_into(Eigen::AngleAxisd(M_PI / 2.0, Eigen::Vector3d::UnitX()).toRotationMatrix(), lmax,
                   quarter_);
  const auto count = Eigen::Index(lmax + 1) * (lmax + 1);
  work_.resize(count);
  cos_.resize(std::size_t(lmax) + 1);
  sin_.resize(std::size_t(lmax) + 1);
}

void WignerPullback::turn_about_z(double theta, ShCoefficients& y) {
  // cos(m theta), sin(m theta) by the angle-addition recurrence: m sincos calls cost more
  // than the products, and the recurrence's error grows only as m eps.
  const double c1 = std::cos(theta), s1 = std::sin(theta);
  cos_[0] = 1.0;
  sin_[0] = 0.0;
  for (int m = 1; m <= lmax_; ++m) {
    cos_[m] = cos_[m - 1] * c1 - sin_[m - 1] * s1;
    sin_[m] = sin_[m - 1] * c1 + cos_[m - 1] * s1;
  }
  // Z(theta) turns the pair (a, b) = (-m, m) by m theta: Z_aa = Z_bb = cos, Z_ab = -Z_ba =
  // sin (the generator u_z); its transpose turns it back.
  for (int l = 1; l <= lmax_; ++l) {
    double* v = y.data() + l * l + l;  // v[m]: coefficient of order m of degree l
    for (int m = 1; m <= l; ++m) {
      const double a = v[-m], b = v[m];
      v[-m] = cos_[m] * a - sin_[m] * b;
      v[m] = sin_[m] * a + cos_[m] * b;
    }
  }
}

void WignerPullback::quarter_turn(const ShCoefficients& x, ShCoefficients& out,
                                  bool transposed) const {
  out[0] = x[0];
  for (int l = 1; l <= lmax_; ++l) {
    const Eigen::Index at = Eigen::Index(l) * l, size = 2 * l + 1;
    if (transposed) {
      out.segment(at, size).noalias() = quarter_[l].transpose() * x.segment(at, size);
    } else {
      out.segment(at, size).noalias() = quarter_[l] * x.segment(at, size);
    }
  }
}

void WignerPullback::apply(const Eigen::Matrix3d& R, const ShCoefficients& x, ShCoefficients& out) {
  require_rotation(R, "R");
  if (x.size() != work_.size()) {
    fail("x: expected (lmax + 1)^2 = ", work_.size(), " coefficients, got ", x.size());
  }
  out.resize(x.size());
  // Near a pole of the zyz angles alpha and gamma are ill-conditioned: there R = Rx(90) R'
  // with R' = Rx(-90) R (rows permuted, exactly) far from it, and U(R)^T = U(R')^T K^T.
  Eigen::Matrix3d turned = R;
  const ShCoefficients* start = &x;
  if (std::abs(R(2, 2)) > M_SQRT1_2) {
    turned.row(1) = R.row(2);
    turned.row(2) = -R.row(1);
    quarter_turn(x, out, true);
    start = &out;
  }
  const double alpha = std::atan2(turned(1, 2), turned(0, 2));
  const double beta = std::atan2(std::hypot(turned(0, 2), turned(1, 2)), turned(2, 2));
  const double gamma = std::atan2(turned(2, 1), -turned(2, 0));
  // U(R')^T = Z(gamma)^T K^T Z(beta)^T K Z(alpha)^T, applied right to left.
  work_ = *start;
  turn_about_z(alpha, work_);
  quarter_turn(work_, out, false);
  turn_about_z(beta, out);
  quarter_turn(out, work_, true);
  turn_about_z(gamma, work_);
  out.swap(work_);  // same size: no copy, and work_ keeps a buffer for the next call
}

WignerGenerators wigner_generators(int lmax) {
  detail::require_degree(lmax, "lmax");
  return build_generators(lmax);
}

void apply_wigner_generator(int axis, const Eigen::Ref<const Eigen::VectorXd>& x,
                            Eigen::Ref<Eigen::VectorXd> y) {
  if (axis < 0 || axis > 2) fail("axis must be 0, 1 or 2 (x, y, z), got ", axis);
  if (x.size() % 2 == 0) fail("x: expected 2l + 1 entries (one degree l), got ", x.size());
  if (y.size() != x.size()) fail("y: expected ", x.size(), " entries, got ", y.size());
  const int l = int(x.size() - 1) / 2;
  y.setZero();
  for_each_generator_entry(l, axis, [&](int r, int c, double v) { y[r] += v * x[c]; });
}

ShCoefficients rotate_coefficients(const ShCoefficients& F, const WignerMatrices& U) {
  const int bandwidth = int(std::lround(std::sqrt(double(F.size()))));
  if (bandwidth < 1 || bandwidth * bandwidth != F.size()) {
    fail("F: expected B^2 coefficients for some bandwidth B >= 1, got ", F.size());
  }
  if (int(U.size()) < bandwidth) {
    fail("U: holds degrees up to ", int(U.size()) - 1, ", F needs up to ", bandwidth - 1);
  }
  ShCoefficients G(F.size());
  for (int l = 0; l < bandwidth; ++l) {
    if (U[l].rows() != 2 * l + 1 || U[l].cols() != 2 * l + 1)
      fail("U[", l, "] is not (2l+1) x (2l+1)");
    G.segment(l * l, 2 * l + 1).noalias() = U[l] * F.segment(l * l, 2 * l + 1);
  }
  return G;
}

}  // namespace spectral_vs
