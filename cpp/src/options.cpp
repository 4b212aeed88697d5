#include "evomesh/options.hpp"

#include <cmath>
#include <string>

#include "evomesh/tet/tet_step.hpp"

namespace evomesh {

namespace {

void require(bool ok, const char* name, const char* range) {
  if (!ok) throw Input_error(std::string(name) + " must be " + range);
}

bool positive(double x) { return std::isfinite(x) && x > 0; }

void validate_common(double radius_scale, double max_samples, int threads) {
  require(radius_scale > 0 && radius_scale <= 1, "radius_scale", "in (0, 1]");
  require(positive(max_samples), "max_samples", "finite and > 0");
  require(threads >= 0, "threads", "0 (the default count) or a positive integer");
}

}  // namespace

void tet::Tet_step_options::validate() const {
  require(positive(cell_factor), "cell_factor", "finite and > 0");
  require(boundary_clearance >= 0 && boundary_clearance < 1, "boundary_clearance", "in [0, 1)");
  require(max_radius_edge == 0 || (std::isfinite(max_radius_edge) && max_radius_edge > 1), "max_radius_edge",
          "0 (none) or a finite number above 1");
  require(sliver_angle >= 0 && sliver_angle <= 30, "sliver_angle", "in [0, 30] degrees");
  validate_common(radius_scale, max_samples, threads);
}

void Quality_options::validate() const {
  require(min_angle > 0 && min_angle <= kMaxMinAngle, "min_angle", "in (0, 30] degrees");
  require(crowding_angle == 0 || (crowding_angle >= 90 && crowding_angle < 180), "crowding_angle",
          "0 (off) or in [90, 180) degrees");
  require(std::isfinite(max_inserted_fraction) && max_inserted_fraction >= 0, "quality_max_fraction",
          "finite and >= 0");
  require(std::isfinite(max_inserted_extra) && max_inserted_extra >= 0, "quality_max_extra", "finite and >= 0");
}

Frfc_options Frfc_options::paper() {
  Frfc_options o;
  o.cell_factor = 1.0;
  o.radius = Radius_rule::exact;
  o.radius_scale = 1.0;
  o.boundary_scale = 1.0;
  o.ring_samples = false;
  o.repair_ratio = 0.0;
  o.demote_ratio = 0.0;
  o.gap_repair_ratio = 0.0;
  o.refine_gap_ratio = 0.0;
  o.samples = Sample_mode::random_grid;
  o.adaptive_cells = false;
  o.skip_coarse = false;
  o.skip_settled = false;
  o.quality = false;
  o.within_domain = false;
  return o;
}

Quality_options Frfc_options::quality_settings() const {
  return {min_angle, crowding_angle, quality_max_fraction, quality_max_extra, quality_rounds};
}

void Frfc_options::validate() const {
  require(positive(cell_factor), "cell_factor", "finite and > 0");
  require(boundary_scale > 0 && boundary_scale <= 1, "boundary_scale", "in (0, 1]");
  require(repair_ratio == 0 || (std::isfinite(repair_ratio) && repair_ratio >= 1), "repair_ratio",
          "None, 0 or a finite number >= 1");
  require(demote_ratio == 0 || (std::isfinite(demote_ratio) && demote_ratio >= 1), "demote_ratio",
          "None, 0 or a finite number >= 1");
  require(gap_repair_ratio == 0 || (std::isfinite(gap_repair_ratio) && gap_repair_ratio >= 1), "gap_repair_ratio",
          "None, 0 or a finite number >= 1");
  require(refine_gap_ratio == 0 || (std::isfinite(refine_gap_ratio) && refine_gap_ratio >= 1), "refine_gap_ratio",
          "None, 0 or a finite number >= 1");
  require(static_cast<int>(samples) <= 3, "samples", "a Sample_mode");
  require(static_cast<int>(radius) <= 2, "radius", "'exact', 'cheap' or 'interpolated'");
  validate_common(radius_scale, max_samples, threads);
  quality_settings().validate();
}

Drfc_options Drfc_options::paper() {
  Drfc_options o;
  o.radius_scale = 1.0;
  o.quality = false;
  o.within_domain = false;
  return o;
}

Quality_options Drfc_options::quality_settings() const {
  return {min_angle, crowding_angle, quality_max_fraction, quality_max_extra, quality_rounds};
}

void Drfc_options::validate() const {
  validate_common(radius_scale, max_samples, threads);
  quality_settings().validate();
}

}  // namespace evomesh
