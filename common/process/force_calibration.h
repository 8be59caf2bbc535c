#pragma once
// VMCS 1999, eqs. 7–10: identifying the cutting coefficients from a measured force
// history. The engaged arc is divided into angular positions β(n) one rotation step
// apart, and the axial discs are as high as the helix lags by one step (eq. 11:
// Dz = R·Δθ/tan h). Every element at position β(n) carries the same elemental force
// (dFx_n, dFy_n), so each sample of the measured Fx, Fy is a sum of elemental forces
// (eq. 8); solving those equations by least squares gives dFx_n, dFy_n; rotating them
// gives dFt_n, dFr_n (eq. 9), and K_T(n) = dFt_n/(Dz·f_t·sin β(n)),
// K_R(n) = dFr_n/dFt_n (eq. 10). Fitting those samples against the chip thickness
// gives the chip-thickness laws (eq. 7, 17); fitting dFt/Dz and dFr/Dz linearly in
// the chip thickness gives the linear edge-force coefficients.
//
// The elemental forces are identifiable when one flute's elements never share the
// arc with another's: engaged arc + helix lag over the axial depth < 2π/N (the
// paper's calibration cuts: radial depth 0.5–2 mm with a 6 mm tool); a full slot with
// four flutes is not (solve() reports the rank deficiency).
#include <Eigen/Core>
#include <string>
#include <vector>

#include "common/process/cutting_force.h"

namespace cnc::process {

struct CalibrationCut {
  Engagement engagement;
  // Samples at θ_j = j·2π/steps_per_rev, j = 0, 1, ... (several revolutions allowed:
  // sample j belongs to the angle j mod steps_per_rev). steps_per_rev must be a
  // multiple of the flute count; Dz follows from eq. 11 and the axial depth is
  // rounded to a whole number of discs.
  int steps_per_rev = 0;
  std::vector<Eigen::Vector2d> fxy;
};

struct CoefficientSample {
  double h = 0;        // chip thickness f_t·sin β, mm
  double kt = 0;       // K_T, N/mm²
  double kr = 0;       // K_R
  double ft_per_mm = 0;  // dFt/Dz, N/mm
  double fr_per_mm = 0;  // dFr/Dz, N/mm
};

struct CalibrationResult {
  std::string error;  // "" on success
  std::vector<CoefficientSample> samples;
  ChipThicknessLaw chip_law;      // power laws fitted in log–log
  LinearEdgeCoefficients linear;  // K_tc, K_te, K_rc, K_re (K_ac, K_ae need Fz: left 0)
  double residual_rms_n = 0;      // of the eq. 8 fit, over all cuts
};

// min_sin: samples with sin β below it are left out of the fits (the chip is too thin
// there for K = dF/(Dz·t_c) to mean anything against noise).
CalibrationResult calibrate(const EndMill& tool, const std::vector<CalibrationCut>& cuts, double min_sin = 0.25);

// A cut's synthetic measured history: the model's forces at the calibration
// discretisation plus Gaussian noise of standard deviation noise_n (fixed seed).
CalibrationCut synthetic_cut(const EndMill& tool, const Material& mat, ForceModel model, const Engagement& e,
                             int steps_per_rev, int revolutions, double noise_n, unsigned seed);

// The disc count eq. 11 gives for this cut at this step count (at least 1).
int calibration_discs(const EndMill& tool, const Engagement& e, int steps_per_rev);

}  // namespace cnc::process
