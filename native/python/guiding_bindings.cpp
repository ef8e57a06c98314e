// _native.guiding: thin bindings of the guiding library (native/src/techniques/guiding/) for
// tests and tools. Arrays in, arrays out; std::invalid_argument becomes ValueError.
#include "render/params.h"
#include "techniques/guiding/device_fit.h"
#include "techniques/guiding/field.h"

#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include <chrono>

#include <cstring>
#include <stdexcept>
#include <string>

namespace nb = nanobind;
using namespace nb::literals;
using namespace px::guiding;
using px::GuidingLobe;
using px::GuidingRegion;
using px::GuidingSample;
using px::GUIDING_MAX_COMPONENTS;

namespace {

// GuidingSample and GuidingRegion as 32-bit words (their numpy views).
constexpr size_t kSampleWords = sizeof(px::GuidingSample) / 4, kRegionWords = sizeof(px::GuidingRegion) / 4;
static_assert(kSampleWords == 12 && kRegionWords == 16, "GuidingSample is 12 words, GuidingRegion 16");

using Doubles = nb::ndarray<const double, nb::c_contig, nb::device::cpu>;

// memcpy for vectors that may be empty: an empty vector's data() may be null, and memcpy with a
// null pointer is undefined even for 0 bytes (UBSan stops there).
void copy_bytes(void* dst, const void* src, size_t bytes) {
    if (bytes) std::memcpy(dst, src, bytes);
}

template <class T>
nb::ndarray<nb::numpy, T> owned(std::vector<T>&& data, std::vector<size_t> shape) {
    auto* v = new std::vector<T>(std::move(data));
    nb::capsule owner(v, [](void* p) noexcept { delete static_cast<std::vector<T>*>(p); });
    return nb::ndarray<nb::numpy, T>(v->data(), shape.size(), shape.data(), owner);
}

// Rows of `cols` doubles (cols 1: a flat array); throws naming the argument otherwise.
size_t rows(const Doubles& a, size_t cols, const char* name) {
    const bool ok = cols == 1 ? a.ndim() == 1 : a.ndim() == 2 && a.shape(1) == cols;
    if (!ok)
        throw std::invalid_argument(std::string(name) + (cols == 1 ? " must be a 1-d array" : " must have shape (N, ") +
                                    (cols == 1 ? "" : std::to_string(cols) + ")"));
    return a.shape(0);
}

Vec3 vec3(const Doubles& a, const char* name) {
    if (a.size() != 3) throw std::invalid_argument(std::string(name) + " must have 3 elements");
    const double* d = a.data();
    return {d[0], d[1], d[2]};
}

Vec3 unit(const double* d, const char* name) {
    const Vec3 v(d[0], d[1], d[2]);
    const double l = length(v);
    if (!(l > 0.0) || !std::isfinite(l)) throw std::invalid_argument(std::string(name) + ": zero or non-finite direction");
    return v * (1.0 / l);
}

// {"weights": (K,), "mus": (K, 3), "kappas": (K,), "distances": (K,) (inf: none), "pivot": (3,)}
nb::dict to_dict(const Vmm& m) {
    std::vector<double> w(m.count), mu(3 * m.count), k(m.count), d(m.count);
    for (uint32_t i = 0; i < m.count; ++i) {
        w[i] = m.weight[i];
        k[i] = m.kappa[i];
        d[i] = m.distance[i];
        mu[3 * i] = m.mu[i].x, mu[3 * i + 1] = m.mu[i].y, mu[3 * i + 2] = m.mu[i].z;
    }
    nb::dict out;
    out["weights"] = owned(std::move(w), {m.count});
    out["mus"] = owned(std::move(mu), {m.count, 3});
    out["kappas"] = owned(std::move(k), {m.count});
    out["distances"] = owned(std::move(d), {m.count});
    out["pivot"] = owned(std::vector<double>{m.pivot.x, m.pivot.y, m.pivot.z}, {3});
    return out;
}

Vmm from_dict(nb::dict d) {
    auto get = [&](const char* key) { return nb::cast<Doubles>(d[key]); };
    const Doubles w = get("weights"), mu = get("mus"), k = get("kappas");
    const size_t n = rows(w, 1, "weights");
    if (n < 1 || n > kMaxComponents) throw std::invalid_argument("a mixture has 1 to 16 lobes");
    if (rows(mu, 3, "mus") != n || rows(k, 1, "kappas") != n)
        throw std::invalid_argument("weights, mus and kappas must have the same length");
    Vmm m;
    m.count = uint32_t(n);
    for (size_t i = 0; i < n; ++i) {
        m.weight[i] = w.data()[i];
        m.kappa[i] = k.data()[i];
        if (!(m.weight[i] >= 0.0) || !(m.kappa[i] >= 0.0) || !std::isfinite(m.kappa[i]))
            throw std::invalid_argument("weights and kappas must be finite and >= 0");
        m.mu[i] = unit(mu.data() + 3 * i, "mus");
        m.distance[i] = kInfinity;
    }
    if (d.contains("distances")) {
        const Doubles dist = get("distances");
        if (rows(dist, 1, "distances") != n) throw std::invalid_argument("distances must have one value per lobe");
        for (size_t i = 0; i < n; ++i) m.distance[i] = dist.data()[i] > 0.0 ? dist.data()[i] : kInfinity;
    }
    if (d.contains("pivot")) m.pivot = vec3(get("pivot"), "pivot");
    return m;
}

std::vector<Vec3> directions(const Doubles& a, const char* name) {
    const size_t n = rows(a, 3, name);
    std::vector<Vec3> out(n);
    for (size_t i = 0; i < n; ++i) out[i] = unit(a.data() + 3 * i, name);
    return out;
}

nb::dict report_dict(const FitReport& r) {
    nb::dict d;
    d["fitted"] = r.fitted;
    d["iterations"] = r.iterations;
    d["log_likelihood"] = r.log_likelihood;
    d["splits"] = r.splits;
    d["merges"] = r.merges;
    return d;
}

// Training samples from arrays (positions and distances optional), as TrainingSample.
std::vector<TrainingSample> training_samples(const Doubles& dirs, const Doubles& weights, const Doubles& pdfs,
                                             nb::object positions, nb::object distances) {
    const size_t n = rows(dirs, 3, "directions");
    if (rows(weights, 1, "weights") != n || rows(pdfs, 1, "pdfs") != n)
        throw std::invalid_argument("directions, weights and pdfs must have the same length");
    Doubles pos, dist;
    if (!positions.is_none()) {
        pos = nb::cast<Doubles>(positions);
        if (rows(pos, 3, "positions") != n) throw std::invalid_argument("positions must have one row per sample");
    }
    if (!distances.is_none()) {
        dist = nb::cast<Doubles>(distances);
        if (rows(dist, 1, "distances") != n) throw std::invalid_argument("distances must have one value per sample");
    }
    std::vector<TrainingSample> out(n);
    for (size_t i = 0; i < n; ++i) {
        const Vec3 w = unit(dirs.data() + 3 * i, "directions");
        TrainingSample& t = out[i];
        for (int a = 0; a < 3; ++a) t.position[a] = pos.is_valid() ? float(pos.data()[3 * i + a]) : 0.0f;
        t.direction[0] = float(w.x), t.direction[1] = float(w.y), t.direction[2] = float(w.z);
        t.weight = float(weights.data()[i]);
        t.pdf = float(pdfs.data()[i]);
        t.distance = dist.is_valid() ? float(std::min(dist.data()[i], 1e30)) : 1e30f;
        if (!(t.weight >= 0.0f) || !std::isfinite(t.weight) || !(t.pdf > 0.0f) || !std::isfinite(t.pdf))
            throw std::invalid_argument("weights must be finite and >= 0, pdfs finite and > 0");
    }
    return out;
}

nb::ndarray<nb::numpy, float> lobe_array(const std::vector<GuidingLobe>& lobes) {
    static_assert(sizeof(GuidingLobe) == 12 * sizeof(float), "GuidingLobe is 12 floats");
    std::vector<float> f(lobes.size() * 12);
    copy_bytes(f.data(), lobes.data(), f.size() * sizeof(float));
    return owned(std::move(f), {lobes.size(), 12});
}

// The device fit (device_fit.h) on its own buffers: records in, mixtures out (tests, bench).
struct DeviceFitter {
    std::shared_ptr<px::Context> ctx;  // first: destroyed last
    px::Buffer samples, regions, lobes;
    std::unique_ptr<DeviceFit> fit;
    RegionTree tree;  // for refine(): a field's, when made from one
    bool has_tree = false;
    uint32_t last_count = 0;
    DeviceFitter(uint32_t region_count, const FitOptions& o, bool parallax, const std::string& device,
                 uint32_t min_samples, float prob, bool adaptive_prob)
        : ctx(px::Context::shared(device)) {
        validate_fit_options(o);
        fit = std::make_unique<DeviceFit>(*ctx, region_count, o, parallax, min_samples, prob, adaptive_prob);
        std::vector<GuidingRegion> r(region_count, GuidingRegion{});
        regions = px::Buffer::with_vector(*ctx, r, px::kStorageUsage);
        std::vector<GuidingLobe> l(size_t(region_count) * GUIDING_MAX_COMPONENTS, GuidingLobe{});
        lobes = px::Buffer::with_vector(*ctx, l, px::kStorageUsage);
        samples = px::Buffer(*ctx, sizeof(GuidingSample), px::kStorageUsage);
        fit->bind(samples, regions, lobes);
    }
    // The device fit a session makes for a field (guiding.cpp): its regions, tree, options,
    // parallax and min_samples, and its records.
    explicit DeviceFitter(const GuidingField& field, const std::string& device) : ctx(px::Context::shared(device)) {
        const px::GuidingParams& p = field.params();
        fit = std::make_unique<DeviceFit>(*ctx, uint32_t(field.region_count()), field.fit_options(), p.parallax != 0,
                                          p.min_samples, p.prob, p.adaptive_prob != 0);
        std::vector<GuidingRegion> r;
        field.write_regions(r);
        regions = px::Buffer::with_vector(*ctx, r, px::kStorageUsage);
        std::vector<GuidingLobe> l;
        field.write_lobes(l);
        lobes = px::Buffer::with_vector(*ctx, l, px::kStorageUsage);
        samples = px::Buffer(*ctx, sizeof(GuidingSample), px::kStorageUsage);
        fit->bind(samples, regions, lobes);
        tree = field.tree();
        has_tree = true;
    }
    uint32_t refine(uint32_t threshold, uint32_t max_regions) {
        if (!has_tree) throw std::invalid_argument("refine needs a DeviceFit made for a field (DeviceFit.for_field)");
        const uint32_t n = fit->refine(tree, threshold, max_regions, regions, lobes);
        fit->bind(samples, regions, lobes);
        return n;
    }
    // Uploads the records, then times the passes alone (submit to fence).
    double run(const GuidingSample* s, size_t n) {
        if (n > (1u << 24)) throw std::invalid_argument("at most 2^24 records per fit");
        const size_t bytes = std::max<size_t>(n, 1) * sizeof(GuidingSample);
        if (samples.size() < bytes) {
            samples = px::Buffer(*ctx, bytes, px::kStorageUsage);
            fit->bind(samples, regions, lobes);
        }
        if (n) samples.upload(s, n * sizeof(GuidingSample));
        last_count = uint32_t(n);
        const auto t0 = std::chrono::steady_clock::now();
        ctx->submit_and_wait([&](VkCommandBuffer cmd) { fit->record(cmd, uint32_t(n)); });
        return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    }
};

}  // namespace

// Session.guiding_mixture (bindings.cpp): the region holding `point` and its mixture.
nb::dict guiding_mixture_at(const GuidingField& field, nb::ndarray<const double, nb::c_contig, nb::device::cpu> point) {
    if (point.size() != 3) throw std::invalid_argument("point must have 3 coordinates");
    const Vec3 p(point.data()[0], point.data()[1], point.data()[2]);
    const uint32_t r = field.region_of(p);
    if (r == px::NO_INDEX) throw std::invalid_argument("the point lies in no guiding region");
    nb::dict d = to_dict(field.mixture(r));
    const Aabb& b = field.region_bounds(r);
    d["region"] = r;
    const RegionInfo info = field.region_info(r);
    d["fits"] = info.fits;
    d["prob"] = info.selection.prob;  // the sampler's probability of the mixture there
    d["nee_prob"] = info.nee_prob;    // and of NEE
    d["score_bsdf"] = info.selection.score_bsdf;  // the learnt second moments (selection.h)
    d["score_chosen"] = info.selection.score_chosen;
    d["min"] = nb::make_tuple(b.lo.x, b.lo.y, b.lo.z);
    d["max"] = nb::make_tuple(b.hi.x, b.hi.y, b.hi.z);
    return d;
}

void bind_guiding(nb::module_& parent) {
    nb::module_ m = parent.def_submodule("guiding", "Path guiding library (vMF mixtures, EM, regions): tests only");

    m.attr("MAX_COMPONENTS") = GUIDING_MAX_COMPONENTS;
    m.attr("SAMPLE_BYTES") = sizeof(GuidingSample);
    m.attr("LOBE_BYTES") = sizeof(GuidingLobe);
    m.attr("REGION_BYTES") = sizeof(GuidingRegion);

    m.def("vmf_pdf", [](Doubles mu, double kappa, Doubles dirs) {
        vec3(mu, "mu");
        const Vec3 u = unit(mu.data(), "mu");
        const auto d = directions(dirs, "dirs");
        std::vector<double> out(d.size());
        for (size_t i = 0; i < d.size(); ++i) out[i] = vmf_pdf(u, kappa, d[i]);
        return owned(std::move(out), {d.size()});
    }, "mu"_a, "kappa"_a, "dirs"_a);
    m.def("vmf_sample", [](Doubles mu, double kappa, Doubles u) {
        vec3(mu, "mu");
        const Vec3 m0 = unit(mu.data(), "mu");
        const size_t n = rows(u, 2, "u");
        std::vector<double> out(3 * n);
        for (size_t i = 0; i < n; ++i) {
            const Vec3 w = vmf_sample(m0, kappa, u.data()[2 * i], u.data()[2 * i + 1]);
            out[3 * i] = w.x, out[3 * i + 1] = w.y, out[3 * i + 2] = w.z;
        }
        return owned(std::move(out), {n, 3});
    }, "mu"_a, "kappa"_a, "u"_a);
    m.def("vmm_pdf", [](nb::dict mix, Doubles dirs, nb::object x, bool parallax) {
        const Vmm v = from_dict(mix);
        const Vec3 p = x.is_none() ? v.pivot : vec3(nb::cast<Doubles>(x), "x");
        const auto d = directions(dirs, "dirs");
        std::vector<double> out(d.size());
        for (size_t i = 0; i < d.size(); ++i) out[i] = v.pdf(d[i], p, parallax);
        return owned(std::move(out), {d.size()});
    }, "mixture"_a, "dirs"_a, "x"_a = nb::none(), "parallax"_a = false);
    m.def("vmm_sample", [](nb::dict mix, Doubles u, nb::object x, bool parallax) {
        const Vmm v = from_dict(mix);
        const Vec3 p = x.is_none() ? v.pivot : vec3(nb::cast<Doubles>(x), "x");
        const size_t n = rows(u, 3, "u");
        std::vector<double> out(3 * n);
        for (size_t i = 0; i < n; ++i) {
            const double* r = u.data() + 3 * i;
            const Vec3 w = v.sample(r[0], r[1], r[2], p, parallax);
            out[3 * i] = w.x, out[3 * i + 1] = w.y, out[3 * i + 2] = w.z;
        }
        return owned(std::move(out), {n, 3});
    }, "mixture"_a, "u"_a, "x"_a = nb::none(), "parallax"_a = false);
    m.def("gpu_lobes", [](nb::dict mix, bool parallax) {
        const Vmm v = from_dict(mix);
        std::vector<GuidingLobe> lobes(kMaxComponents);
        write_gpu_lobes(v, parallax, lobes.data());
        lobes.resize(v.count);
        return lobe_array(lobes);
    }, "mixture"_a, "parallax"_a = true, "GuidingLobe records (K, 12) float32, as the shader reads them.");
    m.def("mean_cosine", &mean_cosine, "kappa"_a);
    m.def("kappa_from_mean_cosine", &kappa_from_mean_cosine, "r"_a);
    m.def("pack_directions", [](Doubles dirs) {
        const auto d = directions(dirs, "dirs");
        std::vector<uint32_t> out(d.size());
        for (size_t i = 0; i < d.size(); ++i) out[i] = pack_direction(d[i]);
        return owned(std::move(out), {d.size()});
    }, "dirs"_a);
    m.def("unpack_directions", [](nb::ndarray<const uint32_t, nb::ndim<1>, nb::c_contig, nb::device::cpu> p) {
        std::vector<double> out(3 * p.shape(0));
        for (size_t i = 0; i < p.shape(0); ++i) {
            const Vec3 w = unpack_direction(p.data()[i]);
            out[3 * i] = w.x, out[3 * i + 1] = w.y, out[3 * i + 2] = w.z;
        }
        return owned(std::move(out), {p.shape(0), 3});
    }, "packed"_a);
    m.def("make_samples", [](Doubles positions, Doubles dirs, Doubles pdfs, Doubles weights, Doubles distances,
                             nb::object regions, nb::object bsdf_pdfs, nb::object contributions, nb::object nee_lights) {
        const auto d = directions(dirs, "dirs");
        const size_t n = d.size();
        if (rows(positions, 3, "positions") != n || rows(pdfs, 1, "pdfs") != n || rows(weights, 1, "weights") != n ||
            rows(distances, 1, "distances") != n)
            throw std::invalid_argument("positions, dirs, pdfs, weights and distances must have one row per sample");
        std::vector<uint32_t> reg(n, px::NO_INDEX);
        if (!regions.is_none()) {
            auto r = nb::cast<nb::ndarray<const uint32_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>>(regions);
            if (r.shape(0) != n) throw std::invalid_argument("regions must have one value per sample");
            std::copy(r.data(), r.data() + n, reg.begin());
        }
        // Optional per-sample values (the learnt probabilities'): `fallback` where not given.
        const auto optional = [n](nb::object o, const char* name, double fallback = 0.0) {
            std::vector<double> v(n, fallback);
            if (o.is_none()) return v;
            Doubles a = nb::cast<Doubles>(o);
            if (rows(a, 1, name) != n) throw std::invalid_argument(std::string(name) + " must have one value per sample");
            std::copy(a.data(), a.data() + n, v.begin());
            return v;
        };
        const std::vector<double> bsdf = optional(bsdf_pdfs, "bsdf_pdfs"), gained = optional(contributions, "contributions"),
                                  nee = optional(nee_lights, "nee_lights", -1.0);
        std::vector<px::GuidingSample> s(n);
        for (size_t i = 0; i < n; ++i) {
            const double* p = positions.data() + 3 * i;
            s[i].position = {float(p[0]), float(p[1]), float(p[2])};
            s[i].region = reg[i];
            s[i].direction = pack_direction(d[i]);
            s[i].pdf = float(pdfs.data()[i]);
            s[i].weight = float(weights.data()[i]);
            s[i].distance = float(std::min(distances.data()[i], 1e30));
            s[i].bsdf_pdf = float(bsdf[i]);
            s[i].contribution = float(gained[i]);
            s[i].nee_light = float(nee[i]);
        }
        std::vector<uint32_t> words(n * kSampleWords);
        copy_bytes(words.data(), s.data(), n * sizeof(px::GuidingSample));
        return owned(std::move(words), {n, kSampleWords});
    }, "positions"_a, "dirs"_a, "pdfs"_a, "weights"_a, "distances"_a, "regions"_a = nb::none(),
       "bsdf_pdfs"_a = nb::none(), "contributions"_a = nb::none(), "nee_lights"_a = nb::none(),
       "GuidingSample records (N, 12) uint32 as the trace loop writes them (direction packed).");

    nb::class_<FitOptions>(m, "FitOptions")
        .def(nb::init<>())
        .def_rw("max_components", &FitOptions::max_components)
        .def_rw("initial_components", &FitOptions::initial_components)
        .def_rw("kappa0", &FitOptions::kappa0)
        .def_rw("kappa_max", &FitOptions::kappa_max)
        .def_rw("max_iterations", &FitOptions::max_iterations)
        .def_rw("tolerance", &FitOptions::tolerance)
        .def_rw("weight_prior", &FitOptions::weight_prior)
        .def_rw("mean_cosine_prior", &FitOptions::mean_cosine_prior)
        .def_rw("mean_cosine_prior_strength", &FitOptions::mean_cosine_prior_strength)
        .def_rw("decay", &FitOptions::decay)
        .def_rw("split_merge", &FitOptions::split_merge)
        .def_rw("split_threshold", &FitOptions::split_threshold)
        .def_rw("split_min_samples", &FitOptions::split_min_samples)
        .def_rw("merge_threshold", &FitOptions::merge_threshold)
        .def_rw("merge_min_samples", &FitOptions::merge_min_samples)
        .def_rw("max_batch", &FitOptions::max_batch);

    // One region's mixture and statistics, fitted batch by batch (stepwise EM).
    nb::class_<VmmState>(m, "Mixture")
        .def("__init__", [](VmmState* s, nb::object init) {
            new (s) VmmState();
            if (!init.is_none()) s->vmm = from_dict(nb::cast<nb::dict>(init));
        }, "init"_a = nb::none())
        .def("fit", [](VmmState& s, Doubles dirs, Doubles weights, Doubles pdfs, const FitOptions& o, nb::object positions,
                       nb::object distances, nb::object pivot, bool parallax) {
            validate_fit_options(o);
            if (s.vmm.count > o.max_components) throw std::invalid_argument("the mixture has more lobes than max_components");
            const auto t = training_samples(dirs, weights, pdfs, positions, distances);
            if (parallax && (positions.is_none() || distances.is_none()))
                throw std::invalid_argument("parallax needs positions and distances");
            Vec3 p = s.vmm.pivot;
            if (!pivot.is_none()) p = vec3(nb::cast<Doubles>(pivot), "pivot");
            if (parallax) move_pivot(s, p);
            else s.vmm.pivot = p;
            const Batch b = make_batch(t.data(), t.size(), 1.0, double(t.size()), p, parallax);
            return report_dict(fit_batch(s, b, o));
        }, "dirs"_a, "weights"_a, "pdfs"_a, "options"_a = FitOptions(), "positions"_a = nb::none(),
           "distances"_a = nb::none(), "pivot"_a = nb::none(), "parallax"_a = false,
           "One batch of stepwise EM (then split/merge when options.split_merge); returns the report.")
        .def("divergence", [](const VmmState& s, Doubles dirs, Doubles weights, Doubles pdfs) {
            const auto t = training_samples(dirs, weights, pdfs, nb::none(), nb::none());
            const Batch b = make_batch(t.data(), t.size(), 1.0, double(t.size()), s.vmm.pivot, false);
            std::vector<double> d = split_divergence(s.vmm, b);
            const size_t n = d.size();
            return owned(std::move(d), {n});
        }, "dirs"_a, "weights"_a, "pdfs"_a, "Each lobe's chi^2 divergence (the split criterion).")
        .def("merge_metric", [](const VmmState& s, uint32_t k, uint32_t l, Doubles mu, double kappa) {
            if (k >= s.vmm.count || l >= s.vmm.count) throw std::invalid_argument("no such lobe");
            return merge_metric(s.vmm, k, l, unit(mu.data(), "mu"), kappa);
        }, "k"_a, "l"_a, "merged_mu"_a, "merged_kappa"_a)
        .def_prop_ro("mixture", [](const VmmState& s) { return to_dict(s.vmm); })
        .def_prop_ro("count", [](const VmmState& s) { return s.vmm.count; })
        .def_prop_ro("fits", [](const VmmState& s) { return s.fits; });

    // Made at guiding_table()'s defaults.
    nb::class_<px::GuidingParams>(m, "GuidingParams")
        .def("__init__", [](px::GuidingParams* p) { new (p) px::GuidingParams(px::RenderParams().guiding); })
        .def_rw("enabled", &px::GuidingParams::enabled)
        .def_rw("prob", &px::GuidingParams::prob)
        .def_rw("parallax", &px::GuidingParams::parallax)
        .def_rw("training_spp", &px::GuidingParams::training_spp)
        .def_rw("min_samples", &px::GuidingParams::min_samples)
        .def_rw("max_components", &px::GuidingParams::max_components)
        .def_rw("split_merge", &px::GuidingParams::split_merge)
        .def_rw("region_splits", &px::GuidingParams::region_splits)
        .def_rw("region_threshold", &px::GuidingParams::region_threshold)
        .def_rw("max_regions", &px::GuidingParams::max_regions)
        .def_rw("probe_x", &px::GuidingParams::probe_x)
        .def_rw("probe_y", &px::GuidingParams::probe_y)
        .def_rw("lobes_phase", &px::GuidingParams::lobes_phase)
        .def_rw("fit", &px::GuidingParams::fit)
        .def_rw("adaptive_prob", &px::GuidingParams::adaptive_prob)
        .def_rw("adaptive_nee", &px::GuidingParams::adaptive_nee);
    m.def("validate_params", &px::validate_guiding_params, "params"_a);

    nb::class_<GuidingField>(m, "GuidingField")
        .def("__init__", [](GuidingField* f, Doubles lo, Doubles hi, const px::GuidingParams& p, uint32_t seed,
                            const FitOptions& o, uint32_t threads) {
            const Vec3 a = vec3(lo, "scene_min"), b = vec3(hi, "scene_max");
            const float fa[3] = {float(a.x), float(a.y), float(a.z)}, fb[3] = {float(b.x), float(b.y), float(b.z)};
            new (f) GuidingField(p, fa, fb, seed, o, threads);
        }, "scene_min"_a, "scene_max"_a, "params"_a = px::RenderParams().guiding, "seed"_a = 0, "options"_a = FitOptions(),
           "threads"_a = 0)
        .def("add_samples", [](GuidingField& f, nb::ndarray<const uint32_t, nb::c_contig, nb::device::cpu> records) {
            if (records.ndim() != 2 || records.shape(1) != kSampleWords)
                throw std::invalid_argument("records must be GuidingSample records, shape (N, 12) uint32");
            nb::gil_scoped_release release;
            f.add_samples(reinterpret_cast<const px::GuidingSample*>(records.data()), records.shape(0));
        }, "records"_a)
        .def("fit", [](GuidingField& f) {
            FieldStats s;
            {
                nb::gil_scoped_release release;
                s = f.fit();
            }
            nb::dict d;
            d["regions"] = s.regions;
            d["regions_fitted"] = s.regions_fitted;
            d["splits"] = s.splits;
            d["merges"] = s.merges;
            d["refinements"] = s.refinements;
            d["em_iterations"] = s.em_iterations;
            d["fit_milliseconds"] = s.fit_milliseconds;
            d["samples_added"] = s.samples_added;
            d["samples_dropped"] = s.samples_dropped;
            d["region_fits"] = s.region_fits;
            return d;
        })
        .def("reset", &GuidingField::reset)
        .def_prop_ro("region_count", &GuidingField::region_count)
        .def_prop_ro("layout_version", &GuidingField::layout_version)
        .def_prop_ro("guiding_pays", &GuidingField::guiding_pays,
                     "The learnt probabilities pay for guiding as a whole (else every region's prob is 0).")
        .def_static("gpu_bytes_per_region", &GuidingField::gpu_bytes_per_region)
        .def("region_of", [](const GuidingField& f, Doubles pts) {
            const size_t n = rows(pts, 3, "points");
            std::vector<uint32_t> out(n);
            for (size_t i = 0; i < n; ++i) {
                const double* p = pts.data() + 3 * i;
                out[i] = f.region_of(Vec3(p[0], p[1], p[2]));
            }
            return owned(std::move(out), {n});
        }, "points"_a)
        .def("mixture", [](const GuidingField& f, uint32_t r) {
            if (r >= f.region_count()) throw std::invalid_argument("no such region");
            return to_dict(f.mixture(r));
        }, "region"_a)
        .def("region_info", [](const GuidingField& f, uint32_t r) {
            if (r >= f.region_count()) throw std::invalid_argument("no such region");
            const RegionInfo i = f.region_info(r);
            const Aabb& b = f.region_bounds(r);
            nb::dict d;
            d["samples"] = i.samples;
            d["pending"] = i.pending;
            d["seen"] = i.seen;
            d["components"] = i.components;
            d["fits"] = i.fits;
            d["prob"] = i.selection.prob;              // the sampler's (0 where guiding does not pay)
            d["chosen_prob"] = i.region_choice;        // the region's own choice
            d["score_bsdf"] = i.selection.score_bsdf;
            d["score_chosen"] = i.selection.score_chosen;
            d["nee_prob"] = i.nee_prob;
            d["min"] = nb::make_tuple(b.lo.x, b.lo.y, b.lo.z);
            d["max"] = nb::make_tuple(b.hi.x, b.hi.y, b.hi.z);
            return d;
        }, "region"_a)
        .def("spatial_order", &GuidingField::spatial_order)
        .def("regions", [](const GuidingField& f) {
            std::vector<px::GuidingRegion> r;
            f.write_regions(r);
            std::vector<float> words(r.size() * kRegionWords);
            copy_bytes(words.data(), r.data(), words.size() * sizeof(float));
            return owned(std::move(words), {r.size(), kRegionWords});
        }, "GuidingRegion records (R, 16) float32 (lobe_count, fits and samples are uint32 bits; 12: prob, 13, 14: "
           "score_bsdf, score_chosen).")
        .def("lobes", [](const GuidingField& f) {
            std::vector<GuidingLobe> l;
            f.write_lobes(l);
            return lobe_array(l);
        }, "GuidingLobe records (R * 16, 12) float32.")
        .def("nodes", [](const GuidingField& f) {
            static_assert(sizeof(px::GuidingNode) == 2 * sizeof(uint32_t), "GuidingNode is 2 words");
            std::vector<px::GuidingNode> n;
            f.write_nodes(n);
            std::vector<uint32_t> words(n.size() * 2);
            copy_bytes(words.data(), n.data(), words.size() * sizeof(uint32_t));
            return owned(std::move(words), {n.size(), 2});
        }, "GuidingNode records (N, 2) uint32: the split's float32 bits, the link (the shaders' region tree).")
        .def("aabbs", [](const GuidingField& f) {
            std::vector<float> a;
            f.write_aabbs(a);
            const size_t n = a.size() / 6;
            return owned(std::move(a), {n, 6});
        });

    nb::class_<DeviceFitter>(m, "DeviceFit")
        .def(nb::init<uint32_t, const FitOptions&, bool, const std::string&, uint32_t, float, bool>(), "regions"_a,
             "options"_a = FitOptions(), "parallax"_a = false, "device"_a = "cpu", "min_samples"_a = 1,
             "prob"_a = 0.5f, "adaptive_prob"_a = true,
             "The device fit (fit.comp) of `regions` untrained regions on the device `device` picks; `prob` "
             "(guiding_prob) until a region learnt its own (guiding_adaptive_prob), or always.")
        .def("fit", [](DeviceFitter& f, nb::ndarray<const uint32_t, nb::c_contig, nb::device::cpu> records) {
            if (records.ndim() != 2 || records.shape(1) != kSampleWords)
                throw std::invalid_argument("records must be GuidingSample records, shape (N, 12) uint32");
            nb::gil_scoped_release release;
            return f.run(reinterpret_cast<const GuidingSample*>(records.data()), records.shape(0));
        }, "records"_a, "One frame's records: bin, fit every region with a batch; returns the passes' milliseconds.")
        .def_static("for_field", [](const GuidingField& field, const std::string& device) {
            return new DeviceFitter(field, device);
        }, "field"_a, "device"_a = "cpu", nb::rv_policy::take_ownership,
           "The device fit a session makes for `field` (its regions, tree, options and records).")
        .def("refine", [](DeviceFitter& f, uint32_t threshold, uint32_t max_regions) {
            nb::gil_scoped_release release;
            return f.refine(threshold, max_regions);
        }, "threshold"_a, "max_regions"_a,
           "Adaptive refinement after the last fit (DeviceFit::refine); returns the regions split.")
        .def("nodes", [](const DeviceFitter& f) {
            if (!f.has_tree) throw std::invalid_argument("nodes needs a DeviceFit made for a field (DeviceFit.for_field)");
            std::vector<px::GuidingNode> n;
            f.tree.write_nodes(n);
            std::vector<uint32_t> words(n.size() * 2);
            copy_bytes(words.data(), n.data(), words.size() * sizeof(uint32_t));
            return owned(std::move(words), {n.size(), 2});
        }, "The region tree's GuidingNode records (N, 2) uint32, as GuidingField.nodes().")
        .def_prop_ro("inherited", [](const DeviceFitter& f) {
            return nb::make_tuple(f.fit->inherited_samples(), f.fit->inherited_fits());
        }, "(samples, fits) the children of refine() inherited (counted in both halves).")
        .def_prop_ro("region_count", [](const DeviceFitter& f) { return f.fit->region_count(); })
        .def_prop_ro("guiding_pays", [](DeviceFitter& f) {
            f.fit->read_tally();
            return f.fit->guiding_pays();
        }, "After a fit: the learnt probabilities pay for guiding as a whole (GuidingField.guiding_pays's rule, "
           "DeviceFit::guiding_pays).")
        .def_prop_ro("mixture_sampled", [](DeviceFitter& f) {
            f.fit->read_tally();
            return f.fit->mixture_sampled();
        }, "After a fit: some region with a mixture samples it and guiding pays (the session keeps guiding's "
           "pipeline).")
        .def("mixture", [](const DeviceFitter& f, uint32_t r) { return to_dict(f.fit->mixture(r)); }, "region"_a)
        .def("state", [](const DeviceFitter& f, uint32_t r) {
            if (r >= f.fit->region_count()) throw std::invalid_argument("no such region");
            const px::GuidingFitRegion s = f.fit->read_states()[r];
            nb::dict d;
            d["components"] = s.count;
            d["fits"] = s.fits;
            d["samples"] = s.samples;
            d["iterations"] = s.iterations;
            d["splits"] = s.splits;
            d["merges"] = s.merges;
            d["log_likelihood"] = s.log_likelihood;
            d["new_samples"] = s.new_samples;
            d["pending"] = s.pending;
            d["pending_zero"] = s.pending_zero;
            d["received"] = s.received;
            // the learnt guiding probability: the sampler's record and the sums behind it
            px::GuidingRegion g;
            f.regions.download(&g, sizeof(g), size_t(r) * sizeof(px::GuidingRegion));
            d["prob"] = g.prob;
            d["score_bsdf"] = g.score_bsdf;
            d["score_chosen"] = g.score_chosen;
            d["selection_samples"] = s.selection_samples;
            d["selection_weight"] = s.selection_weight;
            d["selection_scores"] = std::vector<double>(s.selection_score, s.selection_score + px::GUIDING_SELECTION_CANDIDATES);
            const std::vector<px::GuidingFitLobe> l = f.fit->read_lobes();
            double w = 0.0, c = 0.0;
            for (uint32_t k = 0; k < GUIDING_MAX_COMPONENTS; ++k) {
                w += l[size_t(r) * GUIDING_MAX_COMPONENTS + k].stat_weight;
                c += l[size_t(r) * GUIDING_MAX_COMPONENTS + k].stat_count;
            }
            d["stat_weight"] = w;  // sum w g over the lobes
            d["stat_count"] = c;   // sum g
            d["pivot"] = nb::make_tuple(s.position_mean.x, s.position_mean.y, s.position_mean.z);
            return d;
        }, "region"_a)
        .def("bins", [](const DeviceFitter& f) {
            std::vector<uint32_t> st = f.fit->read_starts(), so = f.fit->read_sorted(f.last_count);
            const size_t a = st.size(), b = so.size();
            return nb::make_tuple(owned(std::move(st), {a}), owned(std::move(so), {b}));
        }, "The last fit's bins: (first slot of each region's lit then unlit samples, the dropped bin's, "
           "total) and the sorted sample indices.")
        .def("regions", [](const DeviceFitter& f) {
            std::vector<float> words(size_t(f.fit->region_count()) * kRegionWords);
            f.regions.download(words.data(), words.size() * sizeof(float));
            const size_t n = f.fit->region_count();
            return owned(std::move(words), {n, kRegionWords});
        }, "GuidingRegion records (R, 16) float32, as the sampler reads them.")
        .def("lobes", [](const DeviceFitter& f) {
            std::vector<GuidingLobe> l(size_t(f.fit->region_count()) * GUIDING_MAX_COMPONENTS);
            f.lobes.download(l.data(), l.size() * sizeof(GuidingLobe));
            return lobe_array(l);
        }, "GuidingLobe records (R * 16, 12) float32.");
}
