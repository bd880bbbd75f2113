// Rotation estimation (paper, section II-C): every check compares the code with an
// independent answer: closed-form harmonics, a Gauss-Legendre quadrature, functions
// rotated point by point, group identities, finite differences, brute-force search.
#include <spectral_vs/rotation/egi_coefficients.hpp>
#include <spectral_vs/rotation/so3.hpp>
#include <spectral_vs/rotation/so3_search.hpp>

#include "test_support.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

namespace spectral_vs {
namespace {

constexpr double kDeg = M_PI / 180.0;

Eigen::Matrix3d axis_angle(const Eigen::Vector3d& axis, double degrees) {
  return Eigen::AngleAxisd(degrees * kDeg, axis.normalized()).toRotationMatrix();
}

Eigen::Vector3d random_unit(std::mt19937& rng) {
  std::normal_distribution<double> g;
  return Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized();
}

// A rotation with its angle, radians, known by construction.
struct KnownRotation {
  Eigen::Matrix3d R;
  double angle;
  std::string name;
};

// The rotations where published implementations break (Euler beta = pi/2, beta near pi,
// negative rotations about z), exact half turns, and random ones.
std::vector<KnownRotation> test_rotations() {
  std::vector<KnownRotation> out;
  auto add = [&](const Eigen::Vector3d& axis, double degrees, const std::string& name) {
    out.push_back({axis_angle(axis, degrees), std::abs(degrees) * kDeg, name});
  };
  const Eigen::Vector3d x = Eigen::Vector3d::UnitX(), y = Eigen::Vector3d::UnitY(),
                        z = Eigen::Vector3d::UnitZ();
  add(x, 90, "90 about x");
  add(y, 90, "90 about y");
  add(x, -90, "-90 about x");
  add(y, -90, "-90 about y");
  add(z, -30, "-30 about z");
  add(z, -90, "-90 about z");
  add(z, -179.9, "-179.9 about z");
  add(x, 179.9, "179.9 about x");
  add(y, 179.9, "179.9 about y");
  add(Eigen::Vector3d(1, 1, 1), 179.9, "179.9 about (1,1,1)");
  add(x, 180, "180 about x");
  add(y, 180, "180 about y");
  add(z, 180, "180 about z");
  add(Eigen::Vector3d(1, 1, 0), 180, "180 about (1,1,0)");
  add(Eigen::Vector3d(1, -2, 3), 180, "180 about (1,-2,3)");
  add(Eigen::Vector3d(0, 1, 1e-9), 90, "90 about nearly y");
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> angle(-180.0, 180.0);
  for (int i = 0; i < 8; ++i) add(random_unit(rng), angle(rng), "random " + std::to_string(i));
  return out;
}

// Normals of a generic, asymmetric shape: clusters of different spread and weight
// around random directions plus a uniform background. No rotation maps it to itself.
Points clustered_normals(int count, std::mt19937& rng) {
  std::normal_distribution<double> g;
  std::uniform_int_distribution<int> pick(0, 9);
  std::vector<Eigen::Vector3d> centres;
  for (int c = 0; c < 7; ++c) centres.push_back(random_unit(rng));
  const double spread[7] = {0.05, 0.1, 0.2, 0.08, 0.3, 0.15, 0.12};
  Points normals(count, 3);
  for (int i = 0; i < count; ++i) {
    const int c = std::min(pick(rng), 7);  // cluster 0..6, 7 = background
    Eigen::Vector3d n(g(rng), g(rng), g(rng));
    if (c < 7) n = centres[c] + spread[c] * n;
    normals.row(i) = n.normalized().transpose();
  }
  return normals;
}

Eigen::Vector3d grid_direction(int j, int k, int bandwidth) {
  const double t = grid_theta(j, bandwidth), p = grid_phi(k, bandwidth);
  return {std::sin(t) * std::cos(p), std::sin(t) * std::sin(p), std::cos(t)};
}

// f(x) = sum_lm F_lm S_lm(x), evaluated pointwise.
double evaluate(const ShCoefficients& F, const Eigen::Vector3d& x) {
  const int lmax = int(std::lround(std::sqrt(double(F.size())))) - 1;
  Eigen::VectorXd s((lmax + 1) * (lmax + 1));
  real_spherical_harmonics(x, lmax, s);
  return F.dot(s);
}

template <typename Function>
SphereGrid sample(int bandwidth, Function f) {
  SphereGrid grid(2 * bandwidth, 2 * bandwidth);
  for (int j = 0; j < 2 * bandwidth; ++j)
    for (int k = 0; k < 2 * bandwidth; ++k) grid(j, k) = f(grid_direction(j, k, bandwidth));
  return grid;
}

ShCoefficients random_coefficients(int bandwidth, std::mt19937& rng) {
  std::normal_distribution<double> g;
  ShCoefficients F(sh_count(bandwidth));
  for (int i = 0; i < F.size(); ++i) F[i] = g(rng);
  return F;
}

// Gauss-Legendre nodes and weights on [-1, 1] by Newton's method on P_n.
void gauss_legendre(int n, std::vector<double>& nodes, std::vector<double>& weights) {
  nodes.resize(n);
  weights.resize(n);
  for (int i = 0; i < n; ++i) {
    double x = std::cos(M_PI * (i + 0.75) / (n + 0.5)), dp = 0.0;
    for (int iteration = 0; iteration < 100; ++iteration) {
      double p0 = 1.0, p1 = x;
      for (int k = 2; k <= n; ++k) {
        const double p2 = ((2.0 * k - 1.0) * x * p1 - (k - 1.0) * p0) / k;
        p0 = p1;
        p1 = p2;
      }
      dp = n * (x * p1 - p0) / (x * x - 1.0);
      const double dx = p1 / dp;
      x -= dx;
      if (std::abs(dx) < 1e-16) break;
    }
    nodes[i] = x;
    weights[i] = 2.0 / ((1.0 - x * x) * dp * dp);
  }
}

double max_abs(const Eigen::MatrixXd& m) { return m.cwiseAbs().maxCoeff(); }

// ---------------------------------------------------------------------------------
// Spherical harmonics and the transform

TEST(SphericalHarmonics, MatchClosedFormsUpToDegreeTwo) {
  std::mt19937 rng(1);
  const double c0 = 0.5 / std::sqrt(M_PI), c1 = std::sqrt(3.0 / (4.0 * M_PI)),
               c2 = 0.5 * std::sqrt(15.0 / M_PI), c20 = 0.25 * std::sqrt(5.0 / M_PI);
  std::vector<Eigen::Vector3d> directions = {Eigen::Vector3d::UnitZ(), -Eigen::Vector3d::UnitZ()};
  for (int i = 0; i < 20; ++i) directions.push_back(random_unit(rng));
  for (const Eigen::Vector3d& n : directions) {
    const double x = n.x(), y = n.y(), z = n.z();
    Eigen::VectorXd expected(9), s(9);
    expected << c0, c1 * y, c1 * z, c1 * x, c2 * x * y, c2 * y * z, c20 * (3 * z * z - 1),
        c2 * x * z, 0.5 * c2 * (x * x - y * y);
    real_spherical_harmonics(3.0 * n, 2, s);  // any length: the direction is normalised
    EXPECT_LT((s - expected).cwiseAbs().maxCoeff(), 1e-14) << n.transpose();
  }
}

TEST(SphericalHarmonics, AreOrthonormalUnderGaussLegendreQuadrature) {
  const int lmax = 24, nz = 30, nphi = 60;  // exact for the degrees involved
  std::vector<double> z, w;
  gauss_legendre(nz, z, w);
  const int count = (lmax + 1) * (lmax + 1);
  Eigen::MatrixXd gram = Eigen::MatrixXd::Zero(count, count);
  Eigen::VectorXd s(count);
  for (int a = 0; a < nz; ++a) {
    for (int b = 0; b < nphi; ++b) {
      const double phi = 2.0 * M_PI * b / nphi, r = std::sqrt(1.0 - z[a] * z[a]);
      real_spherical_harmonics(Eigen::Vector3d(r * std::cos(phi), r * std::sin(phi), z[a]), lmax,
                               s);
      gram.noalias() += (w[a] * 2.0 * M_PI / nphi) * s * s.transpose();
    }
  }
  EXPECT_LT(max_abs(gram - Eigen::MatrixXd::Identity(count, count)), 1e-12);
}

TEST(ShTransform, RoundTripsBandLimitedFunctions) {
  std::mt19937 rng(2);
  for (const int B : {1, 2, 5, 16, 33}) {
    // Powers of linear forms: polynomials of degree <= B - 1, so band-limited to l < B.
    std::vector<Eigen::Vector3d> a;
    for (int i = 0; i < 4; ++i) a.push_back(random_unit(rng));
    const auto f = [&](const Eigen::Vector3d& x) {
      double value = 0.3;
      for (int i = 0; i < 4; ++i) value += std::pow(a[i].dot(x), std::max(0, B - 1 - (i % 2)));
      return value;
    };
    const SphereGrid grid = sample(B, f);
    const SphereGrid back = sh_synthesis(sh_coefficients(grid, B), B);
    EXPECT_LT(max_abs(back - grid), 1e-10) << "B = " << B;
  }
}

TEST(ShTransform, CoefficientsOfASingleHarmonicAreAUnitVector) {
  const int B = 12;
  // Closed forms first (independent of the code under test), then higher degrees.
  const SphereGrid xy = sample(
      B, [](const Eigen::Vector3d& x) { return 0.5 * std::sqrt(15.0 / M_PI) * x.x() * x.y(); });
  ShCoefficients expected = ShCoefficients::Zero(sh_count(B));
  expected[sh_index(2, -2)] = 1.0;
  EXPECT_LT((sh_coefficients(xy, B) - expected).cwiseAbs().maxCoeff(), 1e-13);

  const SphereGrid one = sample(B, [](const Eigen::Vector3d&) { return 1.0; });
  expected.setZero();
  expected[0] = std::sqrt(4.0 * M_PI);
  EXPECT_LT((sh_coefficients(one, B) - expected).cwiseAbs().maxCoeff(), 1e-13);

  for (const auto& lm :
       std::vector<std::pair<int, int>>{{5, -3}, {7, 0}, {11, 11}, {11, -11}, {9, 4}}) {
    const int index = sh_index(lm.first, lm.second);
    const SphereGrid grid = sample(B, [&](const Eigen::Vector3d& x) {
      Eigen::VectorXd s(sh_count(B));
      real_spherical_harmonics(x, B - 1, s);
      return s[index];
    });
    expected.setZero();
    expected[index] = 1.0;
    EXPECT_LT((sh_coefficients(grid, B) - expected).cwiseAbs().maxCoeff(), 1e-12)
        << "l = " << lm.first << ", m = " << lm.second;
  }
}

TEST(ShTransform, TransformObjectAgreesWithTheFreeFunctions) {
  std::mt19937 rng(3);
  const SphericalHarmonicTransform transform(8);
  const ShCoefficients F = random_coefficients(8, rng);
  const SphereGrid grid = transform.inverse(F);
  EXPECT_LT(max_abs(grid - sh_synthesis(F, 8)), 1e-15);
  EXPECT_LT((transform.forward(grid) - F).cwiseAbs().maxCoeff(), 1e-12);
  double total = 0.0;
  for (int j = 0; j < 16; ++j) total += 16 * transform.weight(j);
  EXPECT_NEAR(total, 4.0 * M_PI, 1e-13);  // area of the unit sphere
}

// ---------------------------------------------------------------------------------
// Real Wigner matrices

TEST(Wigner, DegreeOneIsTheRotationInTheOrderYZX) {
  for (const KnownRotation& r : test_rotations()) {
    const WignerMatrices U = wigner_real(r.R, 1);
    const int p[3] = {1, 2, 0};
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) EXPECT_DOUBLE_EQ(U[1](a, b), r.R(p[a], p[b])) << r.name;
  }
}

TEST(Wigner, IsOrthogonalAndHasTheCharacterOfSO3AtDegree32) {
  const int lmax = 32;
  for (const KnownRotation& r : test_rotations()) {
    const WignerMatrices U = wigner_real(r.R, lmax);
    ASSERT_EQ(int(U.size()), lmax + 1);
    for (int l = 0; l <= lmax; ++l) {
      const int size = 2 * l + 1;
      EXPECT_LT(max_abs(U[l].transpose() * U[l] - Eigen::MatrixXd::Identity(size, size)), 1e-12)
          << r.name << ", l = " << l;
      // The character of the degree-l representation: sin((2l+1) t/2) / sin(t/2).
      const double character = std::sin(size * r.angle / 2.0) / std::sin(r.angle / 2.0);
      EXPECT_NEAR(U[l].trace(), character, 1e-11) << r.name << ", l = " << l;
    }
  }
}

TEST(Wigner, IsAHomomorphismAtDegree32) {
  const int lmax = 32;
  const auto rotations = test_rotations();
  for (std::size_t a = 0; a < rotations.size(); ++a) {
    const auto& r1 = rotations[a];
    const auto& r2 = rotations[(a * 7 + 3) % rotations.size()];
    const WignerMatrices U1 = wigner_real(r1.R, lmax), U2 = wigner_real(r2.R, lmax),
                         U12 = wigner_real(r1.R * r2.R, lmax);
    for (int l = 0; l <= lmax; ++l) {
      EXPECT_LT(max_abs(U12[l] - U1[l] * U2[l]), 1e-12)
          << r1.name << " * " << r2.name << ", l = " << l;
    }
  }
}

TEST(Wigner, RotatesTheCoefficientsOfARotatedFunctionAtDegree32) {
  // f of degree <= 32 sampled on a B = 33 grid: the quadrature is exact, so the
  // coefficients of g(x) = f(R^T x), rotated point by point, must equal U(R) F.
  const int B = 33, lmax = 32;
  std::mt19937 rng(4);
  const ShCoefficients F = random_coefficients(B, rng);
  for (const KnownRotation& r : test_rotations()) {
    const SphereGrid g =
        sample(B, [&](const Eigen::Vector3d& x) { return evaluate(F, r.R.transpose() * x); });
    const ShCoefficients G = sh_coefficients(g, B);
    const WignerMatrices U = wigner_real(r.R, lmax);
    double error = 0.0;
    for (int l = 0; l <= lmax; ++l) {
      const Eigen::VectorXd expected = U[l] * F.segment(l * l, 2 * l + 1);
      error = std::max(error, (G.segment(l * l, 2 * l + 1) - expected).cwiseAbs().maxCoeff());
    }
    EXPECT_LT(error, 1e-10) << r.name;
    EXPECT_LT((rotate_coefficients(F, U) - G).cwiseAbs().maxCoeff(), 1e-10) << r.name;
  }
}

TEST(Wigner, IntoReusesStorageAndMatchesWignerReal) {
  WignerMatrices U;
  const auto rotations = test_rotations();
  wigner_real_into(rotations[0].R, 10, U);
  const double* storage = U[10].data();
  wigner_real_into(rotations[5].R, 10, U);
  EXPECT_EQ(U[10].data(), storage);
  const WignerMatrices expected = wigner_real(rotations[5].R, 10);
  for (int l = 0; l <= 10; ++l) EXPECT_EQ(U[l], expected[l]);
}

// The rotations of test_rotations() and those where the pullback's zyz angles change
// branch: the poles (beta = 0, pi), a pole to 1e-9 rad, and both sides of the switch at
// |R(2, 2)| = cos 45 degrees.
std::vector<KnownRotation> pullback_rotations() {
  std::vector<KnownRotation> out = test_rotations();
  const Eigen::Vector3d x = Eigen::Vector3d::UnitX();
  out.push_back({Eigen::Matrix3d::Identity(), 0.0, "identity"});
  out.push_back({axis_angle(x, 1e-7), 1e-7 * kDeg, "1e-7 deg about x"});
  out.push_back({axis_angle(x, 180.0 - 1e-7) * axis_angle(Eigen::Vector3d::UnitZ(), 40.0), 0.0,
                 "near the lower pole"});
  for (const double degrees : {44.999999, 45.0, 45.000001, 135.0}) {
    out.push_back({axis_angle(Eigen::Vector3d(1, 2, 0), degrees), degrees * kDeg,
                   std::to_string(degrees) + " off the pole"});
  }
  return out;
}

TEST(WignerPullback, IsTheTransposeOfWignerRealAtDegree32) {
  const int lmax = 32;
  std::mt19937 rng(6);
  const ShCoefficients x = random_coefficients(lmax + 1, rng);
  WignerPullback pullback(lmax);
  ShCoefficients out;
  for (const KnownRotation& r : pullback_rotations()) {
    const WignerMatrices U = wigner_real(r.R, lmax);
    pullback.apply(r.R, x, out);
    for (int l = 0; l <= lmax; ++l) {
      const Eigen::VectorXd expected = U[l].transpose() * x.segment(l * l, 2 * l + 1);
      EXPECT_LT((out.segment(l * l, 2 * l + 1) - expected).cwiseAbs().maxCoeff(), 1e-12)
          << r.name << ", l = " << l;
    }
  }
}

TEST(WignerPullback, UndoesTheRotationOfASampledFunction) {
  // Independent of the recursion: G, the coefficients of g(x) = f(R^T x) by exact
  // quadrature, pulled back by R are F again.
  const int B = 17;
  std::mt19937 rng(7);
  const ShCoefficients F = random_coefficients(B, rng);
  WignerPullback pullback(B - 1);
  ShCoefficients pulled;
  for (const KnownRotation& r : pullback_rotations()) {
    const SphereGrid g =
        sample(B, [&](const Eigen::Vector3d& p) { return evaluate(F, r.R.transpose() * p); });
    pullback.apply(r.R, sh_coefficients(g, B), pulled);
    EXPECT_LT((pulled - F).cwiseAbs().maxCoeff(), 1e-10) << r.name;
  }
}

TEST(WignerGenerators, AgreeWithCentralDifferencesOfWignerReal) {
  const int lmax = 32;
  const double h = 1e-5;
  const WignerGenerators u = wigner_generators(lmax);
  for (int axis = 0; axis < 3; ++axis) {
    const Eigen::Vector3d e = Eigen::Vector3d::Unit(axis);
    const WignerMatrices plus = wigner_real(Eigen::AngleAxisd(h, e).toRotationMatrix(), lmax);
    const WignerMatrices minus = wigner_real(Eigen::AngleAxisd(-h, e).toRotationMatrix(), lmax);
    const auto& generator = axis == 0 ? u.x : axis == 1 ? u.y : u.z;
    ASSERT_EQ(int(generator.size()), lmax + 1);
    for (int l = 1; l <= lmax; ++l) {
      const Eigen::MatrixXd difference = (plus[l] - minus[l]) / (2.0 * h);
      EXPECT_LT((difference - generator[l]).norm() / generator[l].norm(), 1e-6)
          << "axis " << axis << ", l = " << l;
    }
  }
}

TEST(WignerGenerators, AreSparseAntisymmetricAndSatisfyTheLieBracket) {
  const int lmax = 20;
  const WignerGenerators u = wigner_generators(lmax);
  const WignerGenerators lower = wigner_generators(5);  // the same blocks, fewer of them
  ASSERT_EQ(lower.x.size(), 6u);
  for (int l = 0; l <= 5; ++l) {
    EXPECT_EQ(lower.x[l], u.x[l]);
    EXPECT_EQ(lower.z[l], u.z[l]);
  }
  for (int l = 0; l <= lmax; ++l) {
    for (const auto* g : {&u.x[l], &u.y[l], &u.z[l]}) {
      EXPECT_EQ(*g, -g->transpose());
      for (int r = 0; r < g->rows(); ++r) EXPECT_LE((g->row(r).array() != 0.0).count(), 2);
    }
    // [hat(e_x), hat(e_y)] = hat(e_z) and cyclic: the representation keeps the bracket.
    EXPECT_LT(max_abs(u.x[l] * u.y[l] - u.y[l] * u.x[l] - u.z[l]), 1e-12) << "l = " << l;
    EXPECT_LT(max_abs(u.y[l] * u.z[l] - u.z[l] * u.y[l] - u.x[l]), 1e-12) << "l = " << l;
    EXPECT_LT(max_abs(u.z[l] * u.x[l] - u.x[l] * u.z[l] - u.y[l]), 1e-12) << "l = " << l;
    const Eigen::VectorXd x = Eigen::VectorXd::LinSpaced(2 * l + 1, -1.0, 2.0).array().sin();
    Eigen::VectorXd y(2 * l + 1);
    apply_wigner_generator(1, x, y);
    EXPECT_LT((y - u.y[l] * x).cwiseAbs().maxCoeff(), 1e-14);
  }
}

// ---------------------------------------------------------------------------------
// Correlation, gradient, Hessian

struct CorrelationCase {
  ShCoefficients target, model;
  Eigen::Matrix3d R;
};

CorrelationCase random_case(int B, unsigned seed) {
  std::mt19937 rng(seed);
  CorrelationCase c{random_coefficients(B, rng), random_coefficients(B, rng), Eigen::Matrix3d()};
  c.R = axis_angle(random_unit(rng), 73.0);
  return c;
}

double correlation_at(So3Correlation& correlation, const Eigen::Matrix3d& R,
                      const Eigen::Vector3d& e) {
  const double angle = e.norm();
  const Eigen::Matrix3d step = angle == 0.0
                                   ? Eigen::Matrix3d::Identity()
                                   : Eigen::AngleAxisd(angle, e / angle).toRotationMatrix();
  return correlation.evaluate(R * step).value;
}

// Mixed central second difference of C(R exp(hat e)) at e = 0.
Eigen::Matrix3d hessian_difference(So3Correlation& c, const Eigen::Matrix3d& R, double h) {
  Eigen::Matrix3d H;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      const Eigen::Vector3d a = h * Eigen::Vector3d::Unit(i), b = h * Eigen::Vector3d::Unit(j);
      H(i, j) = (correlation_at(c, R, a + b) - correlation_at(c, R, a - b) -
                 correlation_at(c, R, b - a) + correlation_at(c, R, -a - b)) /
                (4.0 * h * h);
    }
  }
  return H;
}

TEST(So3Correlation, GradientAndHessianAgreeWithFiniteDifferences) {
  for (const bool normalised : {true, false}) {
    for (const int B : {8, 16}) {
      const CorrelationCase c = random_case(B, 10 + B);
      So3Correlation correlation(c.target, c.model, B, normalised);
      const CorrelationValue v = correlation.evaluate(c.R, true);
      const double h = 1e-5;
      Eigen::Vector3d gradient;
      for (int k = 0; k < 3; ++k) {
        const Eigen::Vector3d e = h * Eigen::Vector3d::Unit(k);
        gradient[k] =
            (correlation_at(correlation, c.R, e) - correlation_at(correlation, c.R, -e)) / (2 * h);
      }
      EXPECT_LT((gradient - v.gradient).norm() / v.gradient.norm(), 1e-6) << "B = " << B;
      // Richardson extrapolation of two step sizes cancels the h^2 error term.
      const Eigen::Matrix3d H = (4.0 * hessian_difference(correlation, c.R, 5e-4) -
                                 hessian_difference(correlation, c.R, 1e-3)) /
                                3.0;
      EXPECT_LT((H - v.hessian).norm() / v.hessian.norm(), 1e-6) << "B = " << B;
      EXPECT_EQ(v.hessian, v.hessian.transpose());
      EXPECT_EQ(correlation.evaluate(c.R).hessian, Eigen::Matrix3d::Zero());  // not asked
    }
  }
}

TEST(So3Correlation, IsTheDotProductOfTheCoefficientsAtTheIdentity) {
  const CorrelationCase c = random_case(10, 3);
  So3Correlation raw(c.target, c.model, 10, false);
  EXPECT_NEAR(raw.evaluate(Eigen::Matrix3d::Identity()).value, c.target.dot(c.model), 1e-10);
  ShCoefficients t = c.target, m = c.model;
  t[0] = m[0] = 0.0;
  So3Correlation cosine(c.target, c.model, 10);
  EXPECT_NEAR(cosine.evaluate(Eigen::Matrix3d::Identity()).value, t.dot(m) / (t.norm() * m.norm()),
              1e-14);
}

TEST(So3Correlation, CostIsHalfTheSquaredDistanceOfTheRotatedFunctions) {
  std::mt19937 rng(8);
  const Points normals = clustered_normals(1500, rng);
  const Eigen::Matrix3d R = axis_angle(random_unit(rng), 50.0);
  const Points rotated = normals * R.transpose();
  const int B = 12;
  const ShCoefficients model = egi_coefficients(normals, B), target = egi_coefficients(rotated, B);
  EXPECT_LT(rotation_cost(target, model, R, B), 1e-12);
  EXPECT_LT(rotation_cost(target, model, R, B, false) / target.squaredNorm(), 1e-12);
  So3Correlation cosine(target, model, B);
  const Eigen::Matrix3d other = axis_angle(Eigen::Vector3d(1, 2, 3), 40.0);
  EXPECT_NEAR(rotation_cost(target, model, other, B), 1.0 - cosine.evaluate(other).value, 1e-12);
  // Unnormalised, J = (|G|^2 + |F|^2) / 2 - C since U is orthogonal (Parseval).
  So3Correlation raw(target, model, B, false);
  EXPECT_NEAR(rotation_cost(target, model, other, B, false),
              0.5 * (target.squaredNorm() + model.squaredNorm()) - raw.evaluate(other).value,
              1e-9 * target.squaredNorm());
}

// ---------------------------------------------------------------------------------
// EGI coefficients

double covariance_error(const Points& normals, const Eigen::Matrix3d& R, int B, EgiMethod method) {
  const ShCoefficients F = egi_coefficients(normals, B, method);
  const ShCoefficients G = egi_coefficients(Points(normals * R.transpose()), B, method);
  const ShCoefficients expected = rotate_coefficients(F, wigner_real(R, B - 1));
  return (G - expected).norm() / expected.norm();
}

TEST(EgiCoefficients, ProjectionIsExactlyRotationCovariant) {
  std::mt19937 rng(21);
  const Points normals = clustered_normals(2000, rng);
  for (const int B : {8, 16, 32}) {
    for (int trial = 0; trial < 3; ++trial) {
      const Eigen::Matrix3d R = axis_angle(random_unit(rng), 20.0 + 60.0 * trial);
      EXPECT_LT(covariance_error(normals, R, B, EgiMethod::projection), 1e-12) << "B = " << B;
    }
  }
}

TEST(EgiCoefficients, HistogramIsOnlyApproximatelyCovariant) {
  // Bounds from the measurement in docs/rotation.md (counts on grid cells: about 50 %).
  std::mt19937 rng(22);
  const Points normals = clustered_normals(5000, rng);
  for (const int B : {8, 16, 32}) {
    const Eigen::Matrix3d R = axis_angle(random_unit(rng), 40.0);
    const double error = covariance_error(normals, R, B, EgiMethod::histogram);
    EXPECT_GT(error, 0.05) << "B = " << B;
    EXPECT_LT(error, 1.0) << "B = " << B;
  }
}

TEST(EgiCoefficients, ProjectionOfOneNormalIsTheHarmonicsThere) {
  const Eigen::Vector3d n(0.3, -0.4, 0.5);
  Points normals(2, 3);
  normals.row(0) = n.transpose();
  normals.row(1) = -n.transpose();
  const Eigen::VectorXd weights = Eigen::Vector2d(2.0, 0.0);
  const ShCoefficients F = egi_coefficients(normals, 3, EgiMethod::projection, &weights);
  const double x = 0.3 / n.norm(), y = -0.4 / n.norm();
  EXPECT_NEAR(F[0], 2.0 * 0.5 / std::sqrt(M_PI), 1e-15);
  EXPECT_NEAR(F[sh_index(2, -2)], 2.0 * 0.5 * std::sqrt(15.0 / M_PI) * x * y, 1e-14);
  EXPECT_EQ(egi_coefficients(PointCloud(normals, normals), 3).size(), 9);
}

TEST(EgiCoefficients, SmoothingAppliesTheHeatKernel) {
  std::mt19937 rng(23);
  const ShCoefficients F = random_coefficients(6, rng);
  ShCoefficients S = F;
  smooth_coefficients(S, 6, 0.3);
  EXPECT_DOUBLE_EQ(S[0], F[0]);
  EXPECT_NEAR(S[sh_index(5, -2)], F[sh_index(5, -2)] * std::exp(-30.0 * 0.09 / 2.0), 1e-15);
  ShCoefficients same = F;
  smooth_coefficients(same, 6, 0.0);
  EXPECT_EQ(same, F);
}

// ---------------------------------------------------------------------------------
// Finding the rotation

struct RotatedEgi {
  ShCoefficients model, target;
  Eigen::Matrix3d R;
};

RotatedEgi rotated_egi(int B, const Eigen::Matrix3d& R, unsigned seed) {
  std::mt19937 rng(seed);
  const Points normals = clustered_normals(3000, rng);
  return {egi_coefficients(normals, B), egi_coefficients(Points(normals * R.transpose()), B), R};
}

TEST(RefineRotation, GradientAscentFromTheIdentityConvergesForSmallRotations) {
  const int B = 16;
  std::mt19937 rng(31);
  for (const double degrees : {5.0, 10.0, 15.0, 20.0}) {
    for (const bool newton : {false, true}) {
      const RotatedEgi egi = rotated_egi(B, axis_angle(random_unit(rng), degrees), 40);
      So3Correlation correlation(egi.target, egi.model, B);
      EXPECT_NEAR(correlation.evaluate(egi.R).value, 1.0, 1e-12);
      EXPECT_LT(correlation.evaluate(egi.R).gradient.norm(), 1e-10);
      RotationRefineParams params;
      params.newton = newton;
      params.max_iterations = 500;
      const RotationRefineResult result =
          refine_rotation(correlation, Eigen::Matrix3d::Identity(), params);
      EXPECT_TRUE(result.converged) << degrees << " deg, newton " << newton;
      EXPECT_LT(rotation_distance(result.R, egi.R) / kDeg, 0.01)
          << degrees << " deg, newton " << newton;
      EXPECT_NEAR(result.correlation, 1.0, 1e-9);
    }
  }
}

TEST(So3Search, RecoversAnyRotationThenRefinesBelowOneDegree) {
  for (const int B : {8, 16}) {
    std::mt19937 rng(50 + B);
    const double grid_step = M_PI / B;
    for (double degrees = 10.0; degrees <= 180.0; degrees += 10.0) {
      const RotatedEgi egi =
          rotated_egi(B, axis_angle(random_unit(rng), degrees), 60 + int(degrees));
      const auto candidates = so3_search(egi.target, egi.model, B);
      ASSERT_FALSE(candidates.empty());
      // The best node is within the grid's resolution: |d alpha| + |d beta| + |d gamma|
      // <= pi/(2B) + pi/(4B) + pi/(2B) from the truth for the nearest node.
      EXPECT_LT(rotation_distance(candidates[0].R, egi.R), 1.25 * grid_step)
          << degrees << " deg, B = " << B;
      So3Correlation correlation(egi.target, egi.model, B);
      RotationRefineResult best;
      best.correlation = -2.0;
      for (const auto& candidate : candidates) {
        const auto refined = refine_rotation(correlation, candidate.R);
        if (refined.correlation > best.correlation) best = refined;
      }
      EXPECT_LT(rotation_distance(best.R, egi.R) / kDeg, 1.0) << degrees << " deg, B = " << B;
    }
  }
}

TEST(So3Search, GridValuesAndMaximumMatchABruteForceEvaluation) {
  for (const int B : {4, 8}) {
    const CorrelationCase c = random_case(B, 70 + B);
    So3Correlation correlation(c.target, c.model, B);
    // Every node of the (2B)^3 Euler grid, evaluated directly through wigner_real.
    const int n = 2 * B;
    double best = -2.0;
    Eigen::Matrix3d best_R;
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        for (int k = 0; k < n; ++k) {
          const Eigen::Matrix3d R =
              euler_zyz(M_PI * i / B, M_PI * (2 * j + 1) / (4.0 * B), M_PI * k / B);
          const double v = correlation.evaluate(R).value;
          if (v > best) best = v, best_R = R;
        }
    So3SearchParams params;
    params.candidates = 20;
    const auto candidates = so3_search(c.target, c.model, B, params);
    ASSERT_FALSE(candidates.empty());
    EXPECT_NEAR(candidates[0].correlation, best, 1e-12) << "B = " << B;
    EXPECT_LT(rotation_distance(candidates[0].R, best_R), 1e-9);
    for (std::size_t a = 0; a < candidates.size(); ++a) {
      EXPECT_NEAR(candidates[a].correlation, correlation.evaluate(candidates[a].R).value, 1e-12);
      if (a > 0) {
        EXPECT_LE(candidates[a].correlation, candidates[a - 1].correlation);
      }
    }
  }
}

TEST(So3Search, RefinedMaximumIsTheGlobalMaximumOfAFineBruteForceSearch) {
  const int B = 8;
  const CorrelationCase c = random_case(B, 91);
  So3Correlation correlation(c.target, c.model, B);
  double refined = -2.0;
  for (const auto& candidate : so3_search(c.target, c.model, B)) {
    refined = std::max(refined, refine_rotation(correlation, candidate.R).correlation);
  }
  // An Euler grid 3x finer than the search's, plus random rotations.
  double brute = -2.0;
  const int n = 6 * B;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i)
      for (int k = 0; k < n; ++k) {
        const Eigen::Matrix3d R =
            euler_zyz(2 * M_PI * i / n, M_PI * (j + 0.5) / n, 2 * M_PI * k / n);
        brute = std::max(brute, correlation.evaluate(R).value);
      }
  std::mt19937 rng(92);
  std::normal_distribution<double> g;
  for (int s = 0; s < 20000; ++s) {
    const Eigen::Quaterniond r(g(rng), g(rng), g(rng), g(rng));
    brute = std::max(brute, correlation.evaluate(r.normalized().toRotationMatrix()).value);
  }
  EXPECT_GE(refined, brute - 1e-12);
  EXPECT_LT(refined - brute, 0.05);  // the fine grid comes close to it
}

TEST(So3Search, ThreadsGiveTheSameCandidates) {
  const RotatedEgi egi = rotated_egi(8, axis_angle(Eigen::Vector3d(1, 0, 1), 120.0), 95);
  So3SearchParams two;
  two.threads = 2;
  const auto a = so3_search(egi.target, egi.model, 8),
             b = so3_search(egi.target, egi.model, 8, two);
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].R, b[i].R);
    EXPECT_EQ(a[i].correlation, b[i].correlation);
  }
}

TEST(So3Search, CandidatesAreDistinctLocalMaxima) {
  const CorrelationCase c = random_case(16, 96);
  So3SearchParams params;
  params.candidates = 30;
  const auto candidates = so3_search(c.target, c.model, 16, params);
  EXPECT_GT(candidates.size(), 1u);
  EXPECT_LE(candidates.size(), 30u);
  for (std::size_t a = 0; a < candidates.size(); ++a)
    for (std::size_t b = 0; b < a; ++b)
      EXPECT_GE(rotation_distance(candidates[a].R, candidates[b].R), 1.5 * M_PI / 16 - 1e-12);
}

// ---------------------------------------------------------------------------------
// Bad input

template <typename Call>
std::string error_of(Call call) {
  try {
    call();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "no exception";
}

TEST(RotationInput, WignerPullbackRefusesARotationOrSizeItWasNotMadeFor) {
  WignerPullback pullback(4);
  ShCoefficients out;
  const auto message = [&](const Eigen::Matrix3d& R, int size) {
    return error_of([&] { pullback.apply(R, ShCoefficients::Zero(size), out); });
  };
  EXPECT_NE(message(Eigen::Matrix3d::Identity(), 16).find("x: expected (lmax + 1)^2 = 25"),
            std::string::npos);
  EXPECT_NE(message(-Eigen::Matrix3d::Identity(), 25).find("R is not a rotation matrix"),
            std::string::npos);
  EXPECT_NE(error_of([] { WignerPullback{128}; }).find("lmax"), std::string::npos);
}

TEST(RotationInput, RejectsNonRotations) {
  Eigen::Matrix3d scaled = 2.0 * Eigen::Matrix3d::Identity();
  Eigen::Matrix3d nan = Eigen::Matrix3d::Identity();
  nan(1, 2) = std::nan("");
  const Eigen::Matrix3d reflection = Eigen::Vector3d(1, 1, -1).asDiagonal();
  EXPECT_NE(error_of([&] { wigner_real(scaled, 3); }).find("R is not a rotation matrix"),
            std::string::npos);
  EXPECT_NE(error_of([&] { wigner_real(nan, 3); }).find("R is not finite"), std::string::npos);
  EXPECT_NE(error_of([&] { wigner_real(reflection, 3); }).find("det = -1"), std::string::npos);
  const CorrelationCase c = random_case(4, 1);
  So3Correlation correlation(c.target, c.model, 4);
  EXPECT_NE(error_of([&] { correlation.evaluate(scaled); }).find("R is not a rotation"),
            std::string::npos);
  EXPECT_NE(error_of([&] { refine_rotation(correlation, nan); }).find("R0 is not finite"),
            std::string::npos);
}

TEST(RotationInput, RejectsBadBandwidthsDegreesAndSizes) {
  const std::string range = "must be in [1, 128]";
  EXPECT_NE(error_of([] { SphericalHarmonicTransform t(0); }).find(range), std::string::npos);
  EXPECT_NE(error_of([] { SphericalHarmonicTransform t(129); }).find(range), std::string::npos);
  EXPECT_NE(error_of([] {
              wigner_real(Eigen::Matrix3d::Identity(), 128);
            }).find("lmax must be in [0, 127]"),
            std::string::npos);
  EXPECT_NE(error_of([] { wigner_generators(-1); }).find("lmax"), std::string::npos);
  EXPECT_NE(
      error_of([] { sh_synthesis(ShCoefficients::Zero(15), 4); }).find("expected bandwidth^2 = 16"),
      std::string::npos);
  EXPECT_NE(
      error_of([] { sh_coefficients(SphereGrid::Zero(8, 7), 4); }).find("expected a 8 x 8 grid"),
      std::string::npos);
  const ShCoefficients ok = ShCoefficients::Ones(16);
  EXPECT_NE(
      error_of([&] { So3Correlation(ok, ShCoefficients::Ones(9), 4); }).find("model_coefficients"),
      std::string::npos);
  EXPECT_NE(error_of([&] {
              rotation_cost(ShCoefficients::Ones(9), ok, Eigen::Matrix3d::Identity(), 4);
            }).find("target_coefficients"),
            std::string::npos);
  ShCoefficients uniform = ShCoefficients::Zero(16);
  uniform[0] = 1.0;
  EXPECT_NE(error_of([&] { so3_search(uniform, ok, 4); }).find("no energy at degrees l >= 1"),
            std::string::npos);
  ShCoefficients nan = ok;
  nan[3] = std::nan("");
  EXPECT_NE(error_of([&] { so3_search(nan, ok, 4); }).find("non-finite"), std::string::npos);
  So3SearchParams params;
  params.candidates = 0;
  EXPECT_NE(error_of([&] { so3_search(ok, ok, 4, params); }).find("params.candidates"),
            std::string::npos);
  ShCoefficients c = ok;
  EXPECT_NE(error_of([&] { smooth_coefficients(c, 4, -1.0); }).find("sigma"), std::string::npos);
  EXPECT_NE(error_of([] { egi_coefficients(Points(0, 3), 4); }).find("normals is empty"),
            std::string::npos);
  EXPECT_NE(error_of([] { egi_coefficients(Points::Zero(2, 3), 4); }).find("normals: row 0"),
            std::string::npos);
}

}  // namespace
}  // namespace spectral_vs
