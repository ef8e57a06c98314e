// Parallax-aware fitting (thesis 3.2.8, 4.6.5; Ruppert, Herholz & Lensch 2020, sec. 4): a
// region's samples are reprojected to one pivot, the mean position of its samples (not the
// AABB centre, TECHNIQUES.md), so that the samples of one light share one direction; each
// lobe keeps the harmonic-mean distance to its light, which makes a target point.
#pragma once
#include "techniques/guiding/em.h"

namespace px::guiding {

// A training sample as the host keeps it (GuidingSample decoded).
struct TrainingSample {
    float position[3];
    float direction[3];
    float pdf;
    float weight;
    float distance;  // kInfinity: no next vertex
    float bsdf_pdf = 0;      // the BSDF's own density of the direction (0: unknown or a delta lobe)
    float contribution = 0;  // luminance the path gained along it
};

// Distance of a GuidingSample: infinite at or above GUIDING_DISTANCE_INFINITE, when negative
// or not a number.
double sample_distance(float d);

// The batch of samples seen from `pivot`: with parallax each direction becomes
// normalize(x + d w - pivot) with distance |x + d w - pivot| (samples from infinitely far
// keep theirs); weights are multiplied by weight_scale (reservoir subsampling).
// total_samples: samples the batch stands for, zero-weight ones included.
Batch make_batch(const TrainingSample* samples, size_t count, double weight_scale, double total_samples,
                 const Vec3& pivot, bool parallax);

// Moves the mixture's pivot: lobes with a target keep aiming at it (mu, distance and their
// statistics re-expressed from the new pivot); lobes without one are unchanged.
void move_pivot(VmmState& s, const Vec3& pivot);

}  // namespace px::guiding
