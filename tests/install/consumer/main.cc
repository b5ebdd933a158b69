// Uses the installed artex: generates the coarse template, poses it, fits the EM fitter
// (default pipeline options) to the posed template's vertices and prints the fit's summary.
#include <cstdio>

#include "experiments/config.h"
#include "experiments/pipeline.h"
#include "models/normals.h"
#include "models/skinning.h"
#include "models/template_generator.h"
#include "solvers/em_fitter.h"

int main() {
  artex::BodyShapeOptions shape;
  shape.resolution = 0;
  const artex::Template tmpl = artex::GenerateTemplate(shape);
  artex::Pose pose = artex::Pose::Identity(tmpl.num_joints());
  pose.translation = Eigen::Vector3d(0.02, 0.0, 0.01);
  artex::Scan scan;
  artex::Skinning(tmpl).Apply(pose, &scan.points);
  artex::ComputeVertexNormals(scan.points, tmpl.triangles, &scan.normals);
  scan.colors = Eigen::MatrixX3d::Constant(scan.size(), 3, 0.5);
  scan.color_valid.assign(scan.size(), 0);
  const artex::PipelineOptions options = artex::LoadPipelineOptions(artex::Config());
  artex::EMFitter fitter(tmpl, options.fitting);
  const artex::FitSummary summary = fitter.FitFrame(scan);
  std::printf("artex consumer: %d vertices, %s\n", tmpl.num_vertices(),
              summary.BriefReport().c_str());
  return summary.ok() ? 0 : 1;
}
