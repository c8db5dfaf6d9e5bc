#include "fem/element.hpp"

#include <cmath>

namespace softbody {

namespace {

// The Newton iteration for the polar factor (RotationOfDeformationNewton,
// RotationOfDeformation4):
// Only F with det F > kNewtonConditioning (|F|_F^2 / 3)^(3/2): this bounds the
// ratio of the smallest to the largest singular value from below, so F is
// neither inverted nor nearly singular (the SVD takes the rest).
constexpr double kNewtonConditioning = 1e-3;
// F counts as nearly orthogonal when |F|_F^2 / 3 and det F are within this of 1
// (10 %): the unscaled iteration converges fast from there.
constexpr double kNearlyOrthogonal = 0.1;
// The Frobenius scaling z is used until it is within this of 1 (1 %).
constexpr double kScalingCutoff = 1e-2;
// Squared size of an update below which F was already a rotation (to round-off).
constexpr double kExactRotationUpdate2 = 1e-34;
// Squared size of an update below which the next iterate is the last: an update
// d < 1e-4 leaves an error of at most d^4 / 8 < 2e-17 after one more step.
constexpr double kLastUpdate2 = 1e-8;
// Iteration caps (one matrix; four at once): far above the handful the
// eligible F need; a matrix that reaches them takes the SVD.
constexpr int kMaxNewtonIterations = 40;
constexpr int kMaxBatchIterations = 30;

}  // namespace

Lame LameFromYoungPoisson(double young, double poisson) {
  return {young * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson)),
          young / (2.0 * (1.0 + poisson))};
}

static Mat3 EdgeMatrix(const TetPositions &X) {
  Mat3 Dm;
  Dm.col(0) = (X.row(1) - X.row(0)).transpose();
  Dm.col(1) = (X.row(2) - X.row(0)).transpose();
  Dm.col(2) = (X.row(3) - X.row(0)).transpose();
  return Dm;
}

double SignedVolume(const TetPositions &X) {
  return EdgeMatrix(X).determinant() / 6.0;
}

double LongestEdge(const TetPositions &X) {
  double longest = 0;
  for (int a = 0; a < 4; ++a)
    for (int b = a + 1; b < 4; ++b) longest = std::max(longest, (X.row(a) - X.row(b)).norm());
  return longest;
}

ShapeGradients ComputeShapeGradients(const TetPositions &X) {
  const Mat3 Dm_inv = EdgeMatrix(X).inverse();
  ShapeGradients grad;
  grad.row(1) = Dm_inv.row(0);
  grad.row(2) = Dm_inv.row(1);
  grad.row(3) = Dm_inv.row(2);
  grad.row(0) = -(grad.row(1) + grad.row(2) + grad.row(3));
  return grad;
}

Mat12 ElementStiffness(const ShapeGradients &grad, double volume, const Lame &lame,
                       double shear_scale) {
  const double l = lame.lambda, m = lame.mu, sm = shear_scale * lame.mu;
  Mat12 K;
  for (int a = 0; a < 4; ++a) {
    const Vec3 ga = grad.row(a).transpose();
    for (int b = a; b < 4; ++b) {
      const Vec3 gb = grad.row(b).transpose();
      const Vec3 product = ga.cwiseProduct(gb);
      Mat3 block = l * ga * gb.transpose() + sm * gb * ga.transpose();
      block.diagonal().array() += sm * ga.dot(gb);
      block.diagonal() += (2.0 * m - 2.0 * sm) * product;
      block *= volume;
      K.block<3, 3>(3 * a, 3 * b) = block;
      if (b != a) K.block<3, 3>(3 * b, 3 * a) = block.transpose();
    }
  }
  return K;
}

void ElasticForceAndEnergy(const ShapeGradients &grad, double volume, const Lame &lame,
                           double shear_scale, const TetPositions &u, TetPositions *force,
                           double *energy) {
  // Displacement gradient du_i/dX_j from differences to vertex 0 (the gradients
  // sum to zero, so this is the same H, without the round-off of a large common
  // translation: stiff bodies far from their rest place keep exact energies).
  const TetPositions relative = u.rowwise() - u.row(0);
  const Mat3 H = relative.transpose() * grad;
  const double trace = H.trace(), sm = shear_scale * lame.mu;
  Mat3 stress = sm * (H + H.transpose());
  stress.diagonal() = (lame.lambda * trace) * Vec3::Ones() + 2.0 * lame.mu * H.diagonal();
  *force = volume * grad * stress;  // row a: V (sigma g_a)^T, sigma symmetric
  // strain . stress: normal parts H_ii sigma_ii, shear parts gamma_ij tau_ij.
  double density = 0;
  for (int i = 0; i < 3; ++i) density += H(i, i) * stress(i, i);
  density += (H(0, 1) + H(1, 0)) * stress(0, 1) + (H(1, 2) + H(2, 1)) * stress(1, 2) +
             (H(2, 0) + H(0, 2)) * stress(2, 0);
  *energy = 0.5 * volume * density;
}

Mat3 DeformationGradient(const TetPositions &x, const ShapeGradients &grad) {
  return x.transpose() * grad;
}

Mat3 RotationOfDeformationSvd(const Mat3 &F) {
  const Eigen::JacobiSVD<Mat3> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat3 U = svd.matrixU(), V = svd.matrixV();
  // Eigen orders singular values decreasingly: column 2 is the smallest.
  if (U.determinant() < 0) U.col(2) *= -1.0;
  if (V.determinant() < 0) V.col(2) *= -1.0;
  return U * V.transpose();
}

namespace {

// The steps of the Newton iterations below are always inlined: each iteration
// must compile as one function (speed, and the same fused multiply-adds).
#define SOFTBODY_KERNEL_STEP [[gnu::always_inline]] inline

// One matrix as three columns: m[j][i] = entry (i, j).
// The cofactor matrix of m (columns: cross products of m's columns).
SOFTBODY_KERNEL_STEP void Cofactor(const double (&m)[3][3], double (&out)[3][3]) {
  for (int j = 0; j < 3; ++j) {
    const double *u = m[(j + 1) % 3], *v = m[(j + 2) % 3];
    out[j][0] = u[1] * v[2] - u[2] * v[1];
    out[j][1] = u[2] * v[0] - u[0] * v[2];
    out[j][2] = u[0] * v[1] - u[1] * v[0];
  }
}

// det m from its cofactor matrix c (first column of each).
SOFTBODY_KERNEL_STEP double Determinant(const double (&m)[3][3], const double (&c)[3][3]) {
  return m[0][0] * c[0][0] + m[0][1] * c[0][1] + m[0][2] * c[0][2];
}

SOFTBODY_KERNEL_STEP double SquaredFrobenius(const double (&m)[3][3]) {
  double sum = 0;
  for (int j = 0; j < 3; ++j)
    for (int i = 0; i < 3; ++i) sum += m[j][i] * m[j][i];
  return sum;
}

// The Frobenius scaling z = (|X^-1|_F / |X|_F)^(1/2) of the iteration while
// *scaled; once z is within kScalingCutoff of 1, scaling ends (z = 1).
SOFTBODY_KERNEL_STEP double NewtonScaling(const double (&c)[3][3], double x2, double inverse_det,
                                          bool *scaled) {
  double z = 1.0;
  if (*scaled) {
    const double c2 = SquaredFrobenius(c);
    const double z2 = std::sqrt(c2 / x2) * inverse_det;  // |X^-1|_F / |X|_F
    if (std::abs(z2 - 1.0) > kScalingCutoff)
      z = std::sqrt(z2);
    else
      *scaled = false;
  }
  return z;
}

// X <- a X + b C; returns the squared size of the update.
SOFTBODY_KERNEL_STEP double NewtonUpdate(double a, double b, const double (&c)[3][3],
                                         double (&x)[3][3]) {
  double change2 = 0;
  for (int j = 0; j < 3; ++j)
    for (int i = 0; i < 3; ++i) {
      const double next = a * x[j][i] + b * c[j][i];
      change2 += (next - x[j][i]) * (next - x[j][i]);
      x[j][i] = next;
    }
  return change2;
}

// Four matrices in lanes, x[k][l] = entry k (column-major, k = 3 j + i) of
// matrix l, with their cofactor matrices c and determinants det: marks the
// nearly orthogonal lanes eligible (none converged yet) and replaces
// the others by the identity (no division by a small det); true when any is
// eligible.
SOFTBODY_KERNEL_STEP bool SelectNearlyOrthogonal4(double (&x)[9][4], double (&c)[9][4],
                                                  double (&det)[4], bool (&eligible)[4],
                                                  bool (&converged)[4]) {
  bool any = false;
  for (int l = 0; l < 4; ++l) {
    double x2 = 0;
    for (int k = 0; k < 9; ++k) x2 += x[k][l] * x[k][l];
    eligible[l] = std::abs(x2 / 3.0 - 1.0) <= kNearlyOrthogonal &&
                  std::abs(det[l] - 1.0) <= kNearlyOrthogonal;
    converged[l] = false;
    any = any || eligible[l];
    if (!eligible[l]) {
      for (int k = 0; k < 9; ++k) x[k][l] = c[k][l] = (k % 4 == 0) ? 1.0 : 0.0;
      det[l] = 1.0;
    }
  }
  return any;
}

#undef SOFTBODY_KERNEL_STEP

}  // namespace

bool RotationOfDeformationNewton(const Mat3 &F, Mat3 *R) {
  // Newton iteration for the polar factor (Higham 1986, "Computing the polar
  // decomposition with applications"): X <- (z X + X^-T / z) / 2, X^-T = C / det X
  // with C the cofactor matrix (columns: cross products of the columns of X).
  // Far from orthogonal (|X|_F^2 / 3 or det X off 1 by more than 10 %), the
  // Frobenius-norm scaling z = (|X^-1|_F / |X|_F)^(1/2), until it is within 1 %
  // of 1; unscaled (z = 1) after that. A singular value 1 + e becomes
  // 1 + e^2 / (2 (1 + e)): once an update d is below 1e-4, the iterate after
  // next is off by at most d^4 / 8 < 2e-17, so that one is returned unchecked.
  double x[3][3], c[3][3];  // x[j]: column j of X; c[j]: column j of C
  for (int j = 0; j < 3; ++j)
    for (int i = 0; i < 3; ++i) x[j][i] = F(i, j);
  Cofactor(x, c);
  double det = Determinant(x, c);
  double x2 = SquaredFrobenius(x);
  if (!(det > kNewtonConditioning * (x2 / 3.0) * std::sqrt(x2 / 3.0))) return false;
  bool scaled =
      std::abs(x2 / 3.0 - 1.0) > kNearlyOrthogonal || std::abs(det - 1.0) > kNearlyOrthogonal;
  bool last = false;
  for (int iteration = 0; iteration < kMaxNewtonIterations; ++iteration) {
    const double inverse_det = 1.0 / det;
    const double z = NewtonScaling(c, x2, inverse_det, &scaled);
    const double a = 0.5 * z, b = 0.5 * inverse_det / z;
    if (last) {
      for (int j = 0; j < 3; ++j)
        for (int i = 0; i < 3; ++i) (*R)(i, j) = a * x[j][i] + b * c[j][i];
      return true;
    }
    const double change2 = NewtonUpdate(a, b, c, x);
    if (scaled) x2 = SquaredFrobenius(x);
    if (change2 < kExactRotationUpdate2) {  // converged outright (F was a rotation)
      for (int j = 0; j < 3; ++j)
        for (int i = 0; i < 3; ++i) (*R)(i, j) = x[j][i];
      return true;
    }
    last = !scaled && change2 < kLastUpdate2;
    Cofactor(x, c);
    det = Determinant(x, c);
  }
  return false;
}

void RotationOfDeformation4(const Mat3 *F, Mat3 *R) {
  // The unscaled Newton iteration of RotationOfDeformationNewton on four
  // matrices at once, lane l of every array being matrix l (the loops over
  // lanes vectorise). Lanes that are not nearly orthogonal (|F|_F^2 / 3 or
  // det F off 1 by more than 10 %), or not converged after 30 iterations, take
  // RotationOfDeformation. (The iteration stays in this one function: split
  // into helpers, GCC schedules it more slowly.)
  double x[9][4], c[9][4], det[4], change2[4];
  bool eligible[4], converged[4];
  for (int l = 0; l < 4; ++l)
    for (int j = 0; j < 3; ++j)
      for (int i = 0; i < 3; ++i) x[3 * j + i][l] = F[l](i, j);
  const auto cofactor_and_det = [&]() {
    for (int j = 0; j < 3; ++j) {
      const int u = 3 * ((j + 1) % 3), v = 3 * ((j + 2) % 3);
      for (int l = 0; l < 4; ++l) {
        c[3 * j + 0][l] = x[u + 1][l] * x[v + 2][l] - x[u + 2][l] * x[v + 1][l];
        c[3 * j + 1][l] = x[u + 2][l] * x[v + 0][l] - x[u + 0][l] * x[v + 2][l];
        c[3 * j + 2][l] = x[u + 0][l] * x[v + 1][l] - x[u + 1][l] * x[v + 0][l];
      }
    }
    for (int l = 0; l < 4; ++l) det[l] = x[0][l] * c[0][l] + x[1][l] * c[1][l] + x[2][l] * c[2][l];
  };
  cofactor_and_det();
  const bool any = SelectNearlyOrthogonal4(x, c, det, eligible, converged);
  bool final_round = false;
  for (int iteration = 0; any && iteration < kMaxBatchIterations; ++iteration) {
    double b[4];
    for (int l = 0; l < 4; ++l) {
      b[l] = 0.5 / det[l];
      change2[l] = 0;
    }
    for (int k = 0; k < 9; ++k)
      for (int l = 0; l < 4; ++l) {
        const double next = 0.5 * x[k][l] + b[l] * c[k][l];
        change2[l] += (next - x[k][l]) * (next - x[k][l]);
        x[k][l] = next;
      }
    if (final_round) break;  // one iteration after the last lane's update fell below 1e-4
    bool all = true;
    for (int l = 0; l < 4; ++l) {
      converged[l] = converged[l] || change2[l] < kLastUpdate2;
      all = all && (converged[l] || !eligible[l]);
    }
    final_round = all;
    cofactor_and_det();
  }
  for (int l = 0; l < 4; ++l) {
    if (eligible[l] && converged[l]) {
      for (int j = 0; j < 3; ++j)
        for (int i = 0; i < 3; ++i) R[l](i, j) = x[3 * j + i][l];
    } else {
      R[l] = RotationOfDeformation(F[l]);
    }
  }
}

Mat3 RotationOfDeformation(const Mat3 &F) {
  Mat3 R;
  if (RotationOfDeformationNewton(F, &R)) return R;
  return RotationOfDeformationSvd(F);
}

Mat3 CorotatedElement(const ShapeGradients &grad, double volume, const Lame &lame,
                      double shear_scale, const TetPositions &x, const TetPositions &X,
                      TetPositions *force, double *energy, Mat12 *stiffness) {
  const Mat3 R = RotationOfDeformation(DeformationGradient(x, grad));
  const TetPositions y = x * R - X;  // rows: R^T x_a - X_a
  TetPositions local_force;
  ElasticForceAndEnergy(grad, volume, lame, shear_scale, y, &local_force, energy);
  *force = local_force * R.transpose();  // rows: (R f_a)^T
  if (stiffness) {
    *stiffness = ElementStiffness(grad, volume, lame, shear_scale);
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b)
        stiffness->block<3, 3>(3 * a, 3 * b) =
            R * stiffness->block<3, 3>(3 * a, 3 * b) * R.transpose();
  }
  return R;
}

Mat12 ElementStiffnessReference(const ShapeGradients &grad, double volume, const Lame &lame,
                                double shear_scale) {
  Eigen::Matrix<double, 6, 12> B = Eigen::Matrix<double, 6, 12>::Zero();
  for (int a = 0; a < 4; ++a) {
    const double gx = grad(a, 0), gy = grad(a, 1), gz = grad(a, 2);
    B(0, 3 * a + 0) = gx;  // exx
    B(1, 3 * a + 1) = gy;  // eyy
    B(2, 3 * a + 2) = gz;  // ezz
    B(3, 3 * a + 0) = gy;  // gxy = du/dy + dv/dx
    B(3, 3 * a + 1) = gx;
    B(4, 3 * a + 1) = gz;  // gyz = dv/dz + dw/dy
    B(4, 3 * a + 2) = gy;
    B(5, 3 * a + 0) = gz;  // gzx = dw/dx + du/dz
    B(5, 3 * a + 2) = gx;
  }
  Eigen::Matrix<double, 6, 6> C = Eigen::Matrix<double, 6, 6>::Zero();
  C.topLeftCorner<3, 3>().setConstant(lame.lambda);
  C.topLeftCorner<3, 3>().diagonal().array() += 2.0 * lame.mu;
  C.bottomRightCorner<3, 3>().diagonal().setConstant(shear_scale * lame.mu);
  return volume * B.transpose() * C * B;
}

}  // namespace softbody
