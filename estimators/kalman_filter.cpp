#include "estimators/kalman_filter.hpp"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <type_traits>
#include <vector>

#include "estimators/kalman_filter_fixed.hpp"

namespace pumptherm::estimators {
namespace {

// The dynamic-size path (state counts without a fixed-size one: the disturbance-state filter
// with the voltage rows has 14) takes its products column by column and skips the zero
// coefficients of A_D and C: their augmented states are constants or first-order processes and
// a measurement reads a few states, so most coefficients are zero, and at these sizes Eigen's
// general product spends most of its time packing. The sums are the same equations.

/// The number of leading rows of `a` that hold an off-diagonal coefficient. The rows after them
/// are diagonal: states that are constants or first-order processes of their own.
Eigen::Index CoupledRows(const Eigen::MatrixXd& a) {
  Eigen::Index head = 0;
  for (Eigen::Index k = 0; k < a.cols(); ++k) {
    for (Eigen::Index i = a.rows() - 1; i >= head; --i) {
      if (i != k && a(i, k) != 0.0) {
        head = i + 1;
        break;
      }
    }
  }
  return head;
}

/// The columns with a nonzero coefficient in the first `head` rows of `a`, into `active` (sized
/// a.cols() by the caller); returns their count.
Eigen::Index ActiveColumns(const Eigen::MatrixXd& a, Eigen::Index head,
                           std::vector<Eigen::Index>& active) {
  Eigen::Index count = 0;
  for (Eigen::Index k = 0; k < a.cols(); ++k) {
    bool any = false;
    for (Eigen::Index i = 0; i < head && !any; ++i) any = a(i, k) != 0.0;
    if (any) active[static_cast<std::size_t>(count++)] = k;
  }
  return count;
}

/// y += v x over n contiguous doubles, a pair (one SIMD packet) at a time: Eigen's
/// dynamic-size column expressions spend more instructions on their set-up than on the 14
/// coefficients of a column.
inline void Axpy(double v, const double* x, double* y, Eigen::Index n) {
  using Pair = Eigen::Map<Eigen::Vector2d>;
  using ConstPair = Eigen::Map<const Eigen::Vector2d>;
  Eigen::Index i = 0;
  for (; i + 2 <= n; i += 2) Pair(y + i) += v * ConstPair(x + i);
  if (i < n) y[i] += v * x[i];
}

/// y *= v x over n contiguous doubles, a pair at a time (as Axpy).
inline void ScaleBy(double v, const double* x, double* y, Eigen::Index n) {
  using Pair = Eigen::Map<Eigen::Vector2d>;
  using ConstPair = Eigen::Map<const Eigen::Vector2d>;
  Eigen::Index i = 0;
  for (; i + 2 <= n; i += 2) Pair(y + i).array() *= v * ConstPair(x + i).array();
  if (i < n) y[i] *= v * x[i];
}

/// The column lengths the block paths compile for (the disturbance-state filter with the voltage
/// rows on networks of 3 to 7 temperature states): a sum of columns of a length known at compile
/// time unrolls into SIMD pairs held in registers. Other lengths take the same sums at run time.
constexpr int kFirstColumnLength = 12;
constexpr int kLastColumnLength = 16;

/// Calls f(std::integral_constant<int, N>{}) with N = n when n is one of the compiled column
/// lengths, with N = Eigen::Dynamic otherwise.
template <int N = kFirstColumnLength, class F>
void WithColumnLength(Eigen::Index n, F&& f) {
  if constexpr (N > kLastColumnLength) {
    f(std::integral_constant<int, Eigen::Dynamic>{});
  } else {
    if (n != N) return WithColumnLength<N + 1>(n, f);
    f(std::integral_constant<int, N>{});
  }
}

/// out = first + sum_t v_t col_t over columns of n contiguous doubles, the terms added in the order
/// `terms` gives them (each element's sum is the same sequence of additions at either length).
/// `terms(add)` calls add(v, col) per term; `first` is null for zeros, else scaled by first_scale.
template <int N, class Terms>
void SumColumns(Eigen::Index n, const double* first, double first_scale, Terms&& terms,
                double* out) {
  if constexpr (N == Eigen::Dynamic) {
    if (first != nullptr) {
      for (Eigen::Index i = 0; i < n; ++i) out[i] = first_scale * first[i];
    } else {
      std::fill(out, out + n, 0.0);
    }
    terms([&](double v, const double* col) { Axpy(v, col, out, n); });
  } else {
    using Col = Eigen::Matrix<double, N, 1>;
    Col acc = first != nullptr ? Col(first_scale * Eigen::Map<const Col>(first)) : Col::Zero();
    terms([&](double v, const double* col) { acc += v * Eigen::Map<const Col>(col); });
    Eigen::Map<Col>{out} = acc;
  }
}

/// out = s m^T for a square s (n x n) and m (r x n): out.col(i) = sum_k m(i, k) s.col(k).
template <int N>
void TimesTransposed(const Eigen::MatrixXd& s, const Eigen::MatrixXd& m, Eigen::MatrixXd& out) {
  const Eigen::Index n = s.rows();
  out.resize(n, m.rows());
  for (Eigen::Index i = 0; i < m.rows(); ++i) {
    const auto terms = [&](auto&& add) {
      for (Eigen::Index k = 0; k < n; ++k) {
        const double v = m(i, k);
        if (v != 0.0) add(v, s.col(k).data());
      }
    };
    SumColumns<N>(n, nullptr, 0.0, terms, out.col(i).data());
  }
}

/// m v for m (r x n) and v (n), skipping m's zeros.
void TimesVector(const Eigen::MatrixXd& m, const Eigen::VectorXd& v, Eigen::VectorXd& out) {
  out.setZero(m.rows());
  for (Eigen::Index k = 0; k < m.cols(); ++k) {
    for (Eigen::Index i = 0; i < m.rows(); ++i) {
      const double a = m(i, k);
      if (a != 0.0) out(i) += a * v(k);
    }
  }
}

/// s += sum_r a.col(r) b.col(r)^T (n x n, rank m).
void AddOuterProducts(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b, Eigen::MatrixXd& s) {
  const Eigen::Index n = s.rows();
  for (Eigen::Index j = 0; j < s.cols(); ++j) {
    for (Eigen::Index r = 0; r < a.cols(); ++r) Axpy(b(j, r), a.col(r).data(), s.col(j).data(), n);
  }
}

/// inv = a^-1 for a symmetric positive definite `a` of a fixed size M <= 4; false when `a` is
/// not positive definite (its Cholesky fails). The inverse is Eigen's closed form for these
/// sizes: a solve against the identity takes the general triangular solver, ten times longer.
template <int M>
bool InvertSpdFixed(const Eigen::MatrixXd& a, Eigen::MatrixXd& inv) {
  using Mat = Eigen::Matrix<double, M, M>;
  const Eigen::Map<const Mat> fixed(a.data());
  if (Eigen::LLT<Mat>(fixed).info() != Eigen::Success) return false;
  Eigen::Map<Mat>(inv.data()) = fixed.inverse();
  return true;
}

}  // namespace

bool KalmanFilter::InvertInnovationCovariance() {
  const Eigen::Index m = innov_cov_.rows();
  innov_cov_inv_.resize(m, m);
  // A few readings: a dynamic-size Cholesky spends most of its instructions on its set-up.
  switch (m) {
    case 1:
      return InvertSpdFixed<1>(innov_cov_, innov_cov_inv_);
    case 2:
      return InvertSpdFixed<2>(innov_cov_, innov_cov_inv_);
    case 3:
      return InvertSpdFixed<3>(innov_cov_, innov_cov_inv_);
    case 4:
      return InvertSpdFixed<4>(innov_cov_, innov_cov_inv_);
    default:
      llt_.compute(innov_cov_);
      if (llt_.info() != Eigen::Success) return false;
      innov_cov_inv_ = llt_.solve(Eigen::MatrixXd::Identity(m, m));
      return true;
  }
}

KalmanFilter::KalmanFilter(int n)
    : x_(Eigen::VectorXd::Zero(n)),
      xtmp_(n),
      s_(Eigen::MatrixXd::Identity(n, n)),
      ntmp_(n, n),
      active_(static_cast<std::size_t>(n)) {}

void KalmanFilter::Reset(const Eigen::VectorXd& x, const Eigen::MatrixXd& s) {
  x_ = x;
  s_ = s;
  const Eigen::Index n = x.size();
  xtmp_.resize(n);
  ntmp_.resize(n, n);
  active_.resize(static_cast<std::size_t>(n));
}

void KalmanFilter::AddVariance(int i, double var) {
  if (i < 0 || i >= x_.size() || !(var > 0.0) || !std::isfinite(var)) return;
  s_(i, i) += var;
}

void KalmanFilter::Predict(const Eigen::MatrixXd& ad, const Eigen::VectorXd& bu,
                           const Eigen::MatrixXd& sp) {
  if (detail::PredictFixedSize(ad, bu, sp, x_, s_)) return;
  PropagateByBlocks(ad, bu, CoupledRows(ad));
  s_ += sp;
}

void KalmanFilter::Predict(const Eigen::MatrixXd& ad, const Eigen::VectorXd& bu,
                           const Eigen::VectorXd& sp_diagonal, Eigen::Index coupled_rows) {
  const Eigen::Index n = x_.size();
  if (detail::HasFixedSize(n)) {
    if (sp_dense_.rows() != n) sp_dense_.setZero(n, n);
    sp_dense_.diagonal() = sp_diagonal;
    detail::PredictFixedSize(ad, bu, sp_dense_, x_, s_);
    return;
  }
  assert(CoupledRows(ad) <= coupled_rows);
  PropagateByBlocks(ad, bu, std::min(coupled_rows, n));
  s_.diagonal() += sp_diagonal;
}

void KalmanFilter::PropagateByBlocks(const Eigen::MatrixXd& ad, const Eigen::VectorXd& bu,
                                     Eigen::Index head) {
  WithColumnLength(x_.size(),
                   [&](auto length) { PropagateByBlocks<decltype(length)::value>(ad, bu, head); });
}

template <int N>
void KalmanFilter::PropagateByBlocks(const Eigen::MatrixXd& ad, const Eigen::VectorXd& bu,
                                     Eigen::Index head) {
  // By blocks, A_D = [A11 A12; 0 D] with D diagonal (its first `head` rows coupled, the rest
  // constants or first-order processes), and only A_D's nonzero columns in the coupled rows:
  //   x = A_D x + bu                                   (eq. 30)
  //   S = A_D S A_D^T (+ Sp, by the caller)            (eq. 31) with W^T = S [A11 A12]^T:
  //   S11 = [A11 A12] W^T, S21 = W^T(tail rows) scaled by D, S22 = D S22 D.
  const Eigen::Index n = x_.size();
  const Eigen::Index tail = n - head;
  const Eigen::Index na = ActiveColumns(ad, head, active_);
  for (Eigen::Index i = 0; i < n; ++i) {
    double sum = i < head ? 0.0 : ad(i, i) * x_(i);
    for (Eigen::Index a = 0; a < na && i < head; ++a) {
      const Eigen::Index k = active_[static_cast<std::size_t>(a)];
      sum += ad(i, k) * x_(k);
    }
    xtmp_(i) = sum + bu(i);
  }
  x_.swap(xtmp_);
  for (Eigen::Index i = 0; i < head; ++i) {  // ntmp_.col(i) = S A_D.row(i)^T
    const auto terms = [&](auto&& add) {
      for (Eigen::Index a = 0; a < na; ++a) {
        const Eigen::Index k = active_[static_cast<std::size_t>(a)];
        add(ad(i, k), s_.col(k).data());
      }
    };
    SumColumns<N>(n, nullptr, 0.0, terms, ntmp_.col(i).data());
  }
  for (Eigen::Index j = 0; j < head; ++j) {
    for (Eigen::Index i = 0; i <= j; ++i) {
      double sum = 0.0;
      for (Eigen::Index a = 0; a < na; ++a) {
        const Eigen::Index k = active_[static_cast<std::size_t>(a)];
        sum += ad(j, k) * ntmp_(k, i);
      }
      s_(i, j) = s_(j, i) = sum;
    }
  }
  d_tail_.resize(tail);
  for (Eigen::Index i = 0; i < tail; ++i) d_tail_(i) = ad(head + i, head + i);
  for (Eigen::Index i = 0; i < head; ++i) {  // S21 (contiguous), then S12 = S21^T
    s_.col(i).tail(tail) = ntmp_.col(i).tail(tail).cwiseProduct(d_tail_);
  }
  for (Eigen::Index j = head; j < n; ++j) {
    for (Eigen::Index i = 0; i < head; ++i) s_(i, j) = s_(j, i);
    ScaleBy(ad(j, j), d_tail_.data(), s_.col(j).data() + head, tail);  // S22 = D S22 D
  }
}

const KalmanUpdateReport& KalmanFilter::Update(const Eigen::MatrixXd& c, const Eigen::VectorXd& y,
                                               const Eigen::MatrixXd& sm, CovarianceUpdate form) {
  const Eigen::Index m = c.rows();
  const Eigen::Index n = x_.size();
  report_.measurements = static_cast<int>(m);
  report_.ok = true;
  report_.nis = 0.0;
  report_.innovation.resize(m);
  report_.innovation_var.resize(m);
  if (m == 0) return report_;
  k_.resize(n, m);
  if (detail::UpdateFixedSize(c, y, sm, form, x_, s_, k_, report_)) return report_;
  WithColumnLength(n,
                   [&](auto length) { UpdateByColumns<decltype(length)::value>(c, y, sm, form); });
  return report_;
}

template <int N>
void KalmanFilter::UpdateByColumns(const Eigen::MatrixXd& c, const Eigen::VectorXd& y,
                                   const Eigen::MatrixXd& sm, CovarianceUpdate form) {
  const Eigen::Index m = c.rows();
  const Eigen::Index n = x_.size();
  innov_cov_.resize(m, m);
  s_inv_nu_.resize(m);

  TimesVector(c, x_, nu_);
  nu_ = y - nu_;
  TimesTransposed<N>(s_, c, sct_);  // S- C^T (n x m)
  // C S- C^T + Sm over C's nonzero coefficients (a reading reads a few states).
  innov_cov_ = sm;
  for (Eigen::Index k = 0; k < n; ++k) {
    for (Eigen::Index i = 0; i < m; ++i) {
      const double v = c(i, k);
      if (v == 0.0) continue;
      for (Eigen::Index j = 0; j < m; ++j) innov_cov_(i, j) += v * sct_(k, j);
    }
  }
  report_.innovation = nu_;
  report_.innovation_var = innov_cov_.diagonal();
  // K = S- C^T (C S- C^T + Sm)^-1 (eq. 34) through the m x m inverse: m is a few readings, and
  // a solve with the n columns of S- C^T spends more on Eigen's dynamic-size set-up than on
  // arithmetic.
  if (!InvertInnovationCovariance()) {
    report_.ok = false;
    return;
  }
  for (Eigen::Index r = 0; r < m; ++r) {
    const auto terms = [&](auto&& add) {
      for (Eigen::Index q = 0; q < m; ++q) add(innov_cov_inv_(q, r), sct_.col(q).data());
    };
    SumColumns<N>(n, nullptr, 0.0, terms, k_.col(r).data());
  }
  s_inv_nu_.noalias() = innov_cov_inv_ * nu_;
  report_.nis = nu_.dot(s_inv_nu_);
  for (Eigen::Index r = 0; r < m; ++r) x_ += nu_(r) * k_.col(r);  // eq. 32

  if (form == CovarianceUpdate::kJoseph) {
    // [I - K C] S- [I - K C]^T + K Sm K^T = S- - K U^T - U K^T + K Sy K^T with U = S- C^T and
    // Sy = C S- C^T + Sm. With G = K Sy - U (zero for the exact gain: what is left is the gain's
    // rounding) that is S- + (H K^T + K H^T) / 2, H = G - U = K Sy - 2 U: the Joseph form for
    // any gain, exactly symmetric, in O(n^2 m).
    h_.resize(n, m);
    for (Eigen::Index r = 0; r < m; ++r) {
      const auto terms = [&](auto&& add) {
        for (Eigen::Index q = 0; q < m; ++q) add(innov_cov_(q, r), k_.col(q).data());
      };
      SumColumns<N>(n, sct_.col(r).data(), -2.0, terms, h_.col(r).data());
    }
    AddJosephTerms<N>();
  } else {
    // [I - K C] S- = S- - K (S- C^T)^T: eq. 33, the textbook form.
    h_ = -k_;
    AddOuterProducts(h_, sct_, s_);
  }
}

template <int N>
void KalmanFilter::AddJosephTerms() {
  // S += (H K^T + K H^T) / 2 on the upper triangle, mirrored: column j's rows 0..j. With the
  // column's length known at compile time the whole column is summed in registers (its rows
  // below j are overwritten by the mirror of the later columns, which do not read them).
  const Eigen::Index n = s_.rows();
  const Eigen::Index m = k_.cols();
  for (Eigen::Index j = 0; j < n; ++j) {
    double* col = s_.col(j).data();
    const auto terms = [&](auto&& add) {
      for (Eigen::Index r = 0; r < m; ++r) {
        add(0.5 * h_(j, r), k_.col(r).data());
        add(0.5 * k_(j, r), h_.col(r).data());
      }
    };
    if constexpr (N == Eigen::Dynamic) {
      terms([&](double v, const double* x) { Axpy(v, x, col, j + 1); });
    } else {
      SumColumns<N>(n, col, 1.0, terms, col);
    }
    for (Eigen::Index i = 0; i < j; ++i) s_(j, i) = col[i];
  }
}

}  // namespace pumptherm::estimators
