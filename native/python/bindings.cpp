// nanobind bindings: the only place the core meets Python. C++ exceptions become Python
// exceptions (std::invalid_argument -> ValueError, others -> RuntimeError).
#include "render/pixel_filter.h"
#include "render/session.h"
#include "techniques/guiding/guiding.h"
#include "techniques/irradiance_cache.h"
#include "scene/light_tree.h"

#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include <cstring>
#include <variant>

namespace nb = nanobind;
using namespace nb::literals;

namespace {

template <typename T>
nb::ndarray<nb::numpy, T> to_numpy(std::vector<T>&& data, std::vector<size_t> shape) {
    auto* owned = new std::vector<T>(std::move(data));
    nb::capsule owner(owned, [](void* p) noexcept { delete static_cast<std::vector<T>*>(p); });
    return nb::ndarray<nb::numpy, T>(owned->data(), shape.size(), shape.data(), owner);
}

// A Python value as the core's settings check it (Python's bool is an int: tested first).
px::SettingValue setting_value(nb::handle h) {
    px::SettingValue v;
    v.repr = nb::cast<std::string>(nb::repr(h));
    PyObject* o = h.ptr();
    if (PyBool_Check(o)) {
        v.kind = px::SettingValue::Bool;
        v.number = o == Py_True ? 1 : 0;
    } else if (PyFloat_Check(o)) {
        v.kind = px::SettingValue::Float;
        v.number = PyFloat_AsDouble(o);
    } else if (PyUnicode_Check(o)) {
        v.kind = px::SettingValue::Text;
        v.text = nb::cast<std::string>(h);
    } else if (PyIndex_Check(o)) {  // int, numpy integers
        nb::object index = nb::steal(PyNumber_Index(o));
        int overflow = 0;
        const long long x = index.is_valid() ? PyLong_AsLongLongAndOverflow(index.ptr(), &overflow) : 0;
        if (index.is_valid() && !overflow) {
            v.kind = px::SettingValue::Int;
            v.number = double(x);
        }
        PyErr_Clear();
    }
    return v;
}

}  // namespace

void bind_guiding(nb::module_& m);  // guiding_bindings.cpp
nb::dict guiding_mixture_at(const px::guiding::GuidingField& field,
                            nb::ndarray<const double, nb::c_contig, nb::device::cpu> point);

NB_MODULE(_native, m) {
    m.doc() = "Parallax native core: Vulkan ray-tracing path tracer";

    m.def("devices", [] {
        auto reports = px::Context::enumerate();
        uint32_t chosen = UINT32_MAX;
        try {
            chosen = px::Context::choose(reports, "auto");
        } catch (const std::exception&) {
        }
        nb::list out;
        for (const auto& r : reports) {
            nb::dict d;
            d["index"] = r.index;
            d["name"] = r.name;
            d["type"] = r.type;
            d["ray_tracing"] = r.ray_tracing;
            d["missing"] = r.missing;
            d["chosen"] = r.index == chosen;
            out.append(d);
        }
        return out;
    }, "Every Vulkan device: name, type, whether it can ray-trace (and what it lacks), and "
       "which one device='auto' picks.");

    bind_guiding(m);

    nb::exception<px::DeviceMemoryError>(m, "DeviceMemoryError", PyExc_MemoryError);

    m.def("validation_enabled", &px::validation_enabled,
          "Whether the process's Vulkan instance runs VK_LAYER_KHRONOS_validation (set "
          "PARALLAX_VALIDATION=1 before the first session).");
    m.def("validation_messages",
          [](bool clear) {
              auto messages = px::validation_messages();
              if (clear) px::clear_validation_messages();
              return messages;
          },
          "clear"_a = false,
          "The validation layer's warnings and errors since the last clear (the first 1000).");
    m.def("_validation_self_test",
          [](const std::string& device) { px::validation_self_test(*px::Context::shared(device)); },
          "device"_a = "auto", "Test use only: commits two errors the validation layer must report.");
    m.def("memory",
          [](const std::string& device) {
              auto ctx = px::Context::shared(device);
              nb::dict d;
              d["allocated"] = uint64_t(ctx->memory_allocated());
              d["budget"] = uint64_t(ctx->memory_budget());
              d["heap"] = uint64_t(ctx->memory_heap());
              d["device"] = ctx->report().name;
              return d;
          },
          "device"_a = "auto",
          "Device memory in bytes: what the core holds now (every buffer and acceleration structure "
          "of every session on the device), its budget and the device-local heap.");
    m.def("set_memory_budget",
          [](uint64_t bytes, const std::string& device) { px::Context::shared(device)->set_memory_budget(bytes); },
          "bytes"_a, "device"_a = "auto",
          "Device memory the core may hold on the device, over all its sessions (0: the default, "
          "PARALLAX_MEMORY_BUDGET or a share of the heap). Past it, allocations raise "
          "DeviceMemoryError and the session keeps its previous scene.");

    m.def("background_compiles", &px::background_compiles,
          "Pipelines compiling on worker threads now (Session.background_compile, Session.warm).");
    m.def("wait_for_background_compiles", &px::wait_for_background_compiles, nb::call_guard<nb::gil_scoped_release>(),
          "Blocks until no pipeline compiles in the background (parallax_core calls it at exit).");
    m.def("light_tree_min_lights", &px::light_tree_min_lights,
          "Scenes with at least this many local lights (emissive triangles, point, spot and area "
          "lights) pick them through the light tree (where the session's light_tree setting is on), "
          "fewer from the power CDF alone.");
    m.def("primitive_order",
          [](nb::ndarray<const float, nb::shape<-1, 3>, nb::c_contig, nb::device::cpu> lo,
             nb::ndarray<const float, nb::shape<-1, 3>, nb::c_contig, nb::device::cpu> hi) {
              if (lo.shape(0) != hi.shape(0)) throw std::invalid_argument("lo and hi differ in length");
              std::vector<px::vec3> l(lo.shape(0)), h(hi.shape(0));
              if (!l.empty()) {  // an empty array's (and vector's) data may be null: memcpy's is UB
                  std::memcpy(l.data(), lo.data(), l.size() * sizeof(px::vec3));
                  std::memcpy(h.data(), hi.data(), h.size() * sizeof(px::vec3));
              }
              return px::bvh_order(l, h);
          }, "lo"_a, "hi"_a,
          "The order in which an upload hands primitives with boxes (lo, hi) (N x 3 float32) to "
          "the BVH builder (scene.h bvh_order): a permutation of range(N).");
    m.def("pixel_filter_table",
          [](const std::string& type, float width) {
              const px::EnumItem* item = px::setting("pixel_filter_type").item(type);
              if (!item) throw std::invalid_argument("unknown pixel filter type " + type);
              return px::pixel_filter_table(item->value, width);
          }, "type"_a, "width"_a,
          "The pixel filter's inverted CDF that camera samples are drawn from (render/pixel_filter.h): "
          "PIXEL_FILTER_TABLE_SIZE offsets in pixels, entry i for the CDF value i / (size - 1).");
    using ImageRgba = nb::ndarray<const float, nb::shape<-1, -1, 4>, nb::c_contig, nb::device::cpu>;
    using ImageScalar = nb::ndarray<const float, nb::shape<-1, -1>, nb::c_contig, nb::device::cpu>;
    const auto copy = [](const auto& array, auto& into) {  // an empty array's data may be null
        if (!into.empty()) std::memcpy(into.data(), array.data(), into.size() * sizeof(into[0]));
    };
    m.def("ic_combine",
          [copy](ImageRgba rgba, ImageScalar samples, ImageRgba residual, std::optional<ImageScalar> sequence_variance,
                 std::optional<nb::ndarray<const uint32_t, nb::shape<-1, -1>, nb::c_contig, nb::device::cpu>> paths_only) {
              const uint32_t h = uint32_t(rgba.shape(0)), w = uint32_t(rgba.shape(1));
              if (samples.shape(0) != h || samples.shape(1) != w || residual.shape(0) != h || residual.shape(1) != w ||
                  (sequence_variance && (sequence_variance->shape(0) != h || sequence_variance->shape(1) != w)) ||
                  (paths_only && (paths_only->shape(0) != h || paths_only->shape(1) != w)))
                  throw std::invalid_argument("ic_combine: rgba, samples, residual, sequence_variance and paths_only "
                                              "differ in size");
              const size_t n = size_t(w) * h;
              std::vector<float> image(n * 4), counts(n), variance(sequence_variance ? n : 0);
              std::vector<px::vec4> sums(n);
              copy(rgba, image);
              copy(samples, counts);
              copy(residual, sums);
              std::vector<uint32_t> flags(paths_only ? n : 0);
              if (sequence_variance) copy(*sequence_variance, variance);
              if (paths_only) copy(*paths_only, flags);
              px::ic_combine(image, counts, sums, w, h, variance, flags);
              return to_numpy(std::move(image), {h, w, 4});
          }, "rgba"_a, "samples"_a, "residual"_a, "sequence_variance"_a = nb::none(), "paths_only"_a = nb::none(),
          "Consistent cache mode's image (irradiance_cache.h ic_combine): rgba (H x W x 4) the paths' "
          "means, samples (H x W) their counts, residual (H x W x 4) the sums of cache estimate less "
          "path (rgb) and of its squared norm (a), sequence_variance (H x W, optional) from "
          "ic_sequence_variance, paths_only (H x W uint32, optional) from ic_hand_over; returns the combined "
          "RGBA (H x W x 4).");
    m.def("ic_sequence_variance",
          [copy](ImageRgba first, ImageRgba both) {
              const uint32_t h = uint32_t(both.shape(0)), w = uint32_t(both.shape(1));
              if (first.shape(0) != h || first.shape(1) != w)
                  throw std::invalid_argument("ic_sequence_variance: the snapshots differ in size");
              std::vector<px::vec4> a(size_t(w) * h), b(a.size());
              copy(first, a);
              copy(both, b);
              return to_numpy(px::ic_sequence_variance(a, b), {h, w});
          }, "first"_a, "both"_a,
          "n_b times the variance of the mean of n_b samples of the cache's residual, from IC Residual's "
          "sums (rgb; w: sample count) at n_a and n_b > n_a samples (irradiance_cache.h); H x W, "
          "negative where a part has fewer than 4 samples.");
    m.def("ic_hand_over",
          [copy](nb::ndarray<const uint32_t, nb::shape<-1, -1>, nb::c_contig, nb::device::cpu> paths_only,
                 ImageScalar residual_variance, ImageScalar path_variance, ImageScalar means) {
              const uint32_t h = uint32_t(paths_only.shape(0)), w = uint32_t(paths_only.shape(1));
              for (const auto* a : {&residual_variance, &path_variance, &means})
                  if (a->shape(0) != h || a->shape(1) != w)
                      throw std::invalid_argument("ic_hand_over: the per-pixel arrays differ in size");
              const size_t n = size_t(w) * h;
              std::vector<uint32_t> flags(n);
              std::vector<float> residual(n), paths(n), mean(n);
              copy(paths_only, flags);
              copy(residual_variance, residual);
              copy(path_variance, paths);
              copy(means, mean);
              px::ic_hand_over(flags, residual, paths, mean, w, h);
              return to_numpy(std::move(flags), {h, w});
          }, "paths_only"_a, "residual_variance"_a, "path_variance"_a, "means"_a,
          "Consistent cache mode's pixel handover (irradiance_cache.h ic_hand_over): the flags (H x W uint32) "
          "after one snapshot's residual and path variances (ic_sequence_variance) and the pixels' means.");
    m.def("ic_grid",
          [](nb::ndarray<const float, nb::shape<-1, 3>, nb::c_contig, nb::device::cpu> positions,
             nb::ndarray<const float, nb::shape<-1>, nb::c_contig, nb::device::cpu> radii, float accuracy,
             float min_radius) {
              if (positions.shape(0) != radii.shape(0))
                  throw std::invalid_argument("ic_grid: positions and radii differ in length");
              std::vector<px::IcEntry> entries(radii.shape(0));
              for (size_t i = 0; i < entries.size(); ++i) {
                  entries[i].position = {positions(i, 0), positions(i, 1), positions(i, 2)};
                  entries[i].radius = radii(i);
              }
              const px::IcGrid grid = px::ic_grid(entries, accuracy, min_radius);
              nb::dict out;
              out["cell"] = grid.cell;
              out["levels"] = grid.levels;
              out["starts"] = grid.starts;
              std::vector<uint32_t> slots;
              std::vector<float> reach;
              for (const px::IcCandidate& c : grid.candidates) {
                  slots.push_back(c.slot);
                  reach.push_back(c.reach);
              }
              out["slots"] = slots;
              out["reach"] = reach;
              return out;
          }, "positions"_a, "radii"_a, "accuracy"_a, "min_radius"_a,
          "The irradiance cache's lookup grid over entries at `positions` (N x 3) with radii R (irradiance_cache.h "
          "ic_grid): dict of cell, levels, starts (after the levels' header), and slots and reach (accuracy R) per place.");
    m.def("set_light_tree_min_lights", &px::set_light_tree_min_lights, "n"_a,
          "Sets light_tree_min_lights for scenes updated from now on (0 or 1: always the tree; "
          "2**32 - 1: never); a benchmark and test knob.");

    nb::dict limits;  // px::SceneLimits: what update() accepts (README "Limits")
    limits["radiance"] = px::SceneLimits::radiance;
    limits["albedo"] = px::SceneLimits::albedo;
    limits["ior_min"] = px::SceneLimits::ior_min;
    limits["ior_max"] = px::SceneLimits::ior_max;
    limits["coordinate"] = px::SceneLimits::coordinate;
    limits["precision"] = px::SceneLimits::precision;
    limits["camera_scale"] = px::SceneLimits::camera_scale;
    m.attr("LIMITS") = limits;

    // The settings and passes tables (render/params.h): parallax_core wraps each row in a
    // namedtuple (SETTINGS, PASSES) and makes RenderParams from the core rows.
    nb::list settings;
    for (const px::SettingInfo& r : px::settings()) {
        nb::dict d;
        d["name"] = r.name;
        d["technique"] = r.technique;
        const bool is_int = r.type == px::SettingType::Int;
        nb::object lo = nb::none(), hi = nb::none();
        switch (r.type) {
        case px::SettingType::Bool:
            d["type"] = "bool";
            d["default"] = nb::bool_(r.default_value != 0);
            break;
        case px::SettingType::Int:
            d["type"] = "int";
            d["default"] = nb::int_(int64_t(r.default_value));
            break;
        case px::SettingType::Float:
            d["type"] = "float";
            d["default"] = nb::float_(r.default_value);
            break;
        case px::SettingType::Enum:
            d["type"] = "enum";
            d["default"] = nb::str(r.item(uint32_t(r.default_value))->name);
            break;
        }
        if (r.type == px::SettingType::Int || r.type == px::SettingType::Float) {
            lo = is_int ? nb::object(nb::int_(int64_t(r.min))) : nb::object(nb::float_(r.min));
            hi = is_int ? nb::object(nb::int_(int64_t(r.max))) : nb::object(nb::float_(r.max));
        }
        d["min"] = lo;
        d["max"] = hi;
        nb::list items;
        for (const px::EnumItem& i : r.items) items.append(nb::make_tuple(i.name, i.label, i.description));
        d["items"] = nb::tuple(items);
        d["label"] = r.label;
        d["tooltip"] = r.tooltip;
        d["panel"] = r.panel;
        d["group"] = r.group;
        d["unit"] = r.unit;
        d["core"] = r.core();
        settings.append(d);
    }
    m.attr("_SETTINGS") = nb::tuple(settings);
    nb::list passes;
    for (const px::PassInfo& p : px::passes()) {
        nb::dict d;
        d["name"] = p.name;
        d["label"] = p.label;
        d["channels"] = p.channels;
        d["channel_ids"] = p.channel_ids;
        d["description"] = p.description;
        d["technique"] = p.technique;
        d["setting"] = p.setting;
        d["core"] = p.core();
        passes.append(d);
    }
    m.attr("_PASSES") = nb::tuple(passes);
    m.def("_setting_index",
          [](const std::string& name) {
              const px::SettingInfo& row = px::setting(name);
              return size_t(&row - px::settings().data());
          },
          "name"_a, "The row of the setting `name` in SETTINGS (ValueError listing the names if none).");

    // px::RenderParams, opaque: made from {name: value} by the core, which checks each value's
    // type, range or enum name and then the relations between settings (ValueError naming it).
    nb::class_<px::RenderParams>(m, "_RenderParams");
    m.def("_make_params",
          [](nb::dict values) {
              px::RenderParams p;
              for (auto [key, value] : values) {
                  const std::string name = nb::cast<std::string>(key);
                  px::set_setting(p, name, setting_value(value));
              }
              px::validate(p);
              return p;
          },
          "values"_a, "px::RenderParams from {setting: value} (core settings only), checked.");

    nb::class_<px::Session>(m, "Session")
        .def(nb::init<uint32_t, uint32_t, const std::string&>(), "width"_a, "height"_a, "device"_a = "auto",
             nb::call_guard<nb::gil_scoped_release>())
        .def("_update",
             [](px::Session& s, nb::dict arrays, bool spatial_order, const std::vector<std::string>& parts) {
                 const uint32_t mask = px::parse_scene_parts(parts);
                 px::SceneArrays views;
                 std::vector<nb::ndarray<nb::c_contig, nb::device::cpu>> keep;
                 for (auto [key, value] : arrays) {
                     std::string name = nb::cast<std::string>(key);
                     nb::ndarray<nb::c_contig, nb::device::cpu> a;
                     if (!nb::try_cast(value, a))
                         throw nb::type_error(("scene array '" + name + "' must be a C-contiguous numpy array").c_str());
                     px::ArrayView v;
                     v.data = a.data();
                     for (size_t i = 0; i < a.ndim(); ++i) v.shape.push_back(a.shape(i));
                     auto dt = a.dtype();
                     v.kind = dt.code == uint8_t(nb::dlpack::dtype_code::Float) ? 'f'
                              : dt.code == uint8_t(nb::dlpack::dtype_code::UInt) ? 'u'
                              : dt.code == uint8_t(nb::dlpack::dtype_code::Int)  ? 'i'
                                                                                 : '?';
                     v.itemsize = dt.bits / 8;
                     views[name] = v;
                     keep.push_back(a);
                 }
                 nb::gil_scoped_release release;
                 // The primitive order is for builders that split in input order (lavapipe).
                 return s.update(views, spatial_order && s.device().builds_in_input_order(), mask);
             },
             "arrays"_a, "spatial_order"_a = true, "parts"_a = std::vector<std::string>(),
             "Replace the scene with SceneData.flatten() arrays; returns warnings. With `parts` (names "
             "from geometry, instances, materials, lights, camera; empty = all), `arrays` holds only "
             "those parts' arrays and the rest of the last update's scene is kept. `spatial_order` puts "
             "triangles and instances in bvh_order where the device's BVH builder splits in input order "
             "(lavapipe); GPU drivers build their own trees, so there it changes nothing.")
        .def("_set_params", &px::Session::set_params, "params"_a, nb::call_guard<nb::gil_scoped_release>())
        .def("render", &px::Session::render, "frames"_a = 1, nb::call_guard<nb::gil_scoped_release>(),
             "Render `frames` frames of samples_per_frame samples each (GIL released); returns the "
             "frames completed (fewer when cancel() stopped it).")
        .def("cancel", &px::Session::cancel,
             "From any thread: stop the render()/render_rows() call in progress at its next dispatch "
             "(within about a second on lavapipe), or the next call if none is in progress.")
        .def("read",
             [](px::Session& s, const std::string& pass) {
                 uint32_t channels = 0;
                 std::vector<float> data;
                 {
                     nb::gil_scoped_release release;
                     data = s.read(pass, channels);
                 }
                 return to_numpy(std::move(data), {s.height(), s.width(), channels});
             },
             "name"_a, "Accumulated pass as float32 (height, width, channels), row 0 = top.")
        .def_prop_rw("passes", &px::Session::passes, &px::Session::set_passes,
                     "The passes the film holds, by name (combined always; default: every pass). Fewer "
                     "passes, less film memory and fewer writes per sample; a pass whose technique is "
                     "off reads as zeros and takes no memory. Setting it resets accumulation.")
        .def("render_rows", &px::Session::render_rows, "rows"_a, nb::call_guard<nb::gil_scoped_release>(),
             "Trace the next `rows` rows of the current frame (GIL released); True when that "
             "completed the frame. For short, interruptible dispatches.")
        .def_prop_ro("next_row", &px::Session::next_row)
        .def("compile", &px::Session::compile, nb::call_guard<nb::gil_scoped_release>(),
             "Compile the pipelines the next render needs, without rendering (GIL released).")
        .def_prop_rw("background_compile", &px::Session::background_compile, &px::Session::set_background_compile,
                     "Off (default): a render waits for the pipelines it needs. On: while a technique's "
                     "pipelines compile on a worker thread, frames render with the techniques off; "
                     "stats()['fallback_samples'] counts them, and the film starts over with the "
                     "techniques' first frame (F12 and the viewport turn it on).")
        .def_prop_ro("fallback_film", &px::Session::fallback_film,
                     "Whether the film holds only samples rendered while the techniques compiled (cheap, "
                     "unlike stats()); they do not count towards a sample target.")
        .def("warm", &px::Session::warm, nb::call_guard<nb::gil_scoped_release>(),
             "Start compiling the pipelines the current settings need (and their fallback with the "
             "techniques off) on a worker thread; returns at once.")
        .def_prop_ro("pipeline_ready", &px::Session::pipeline_ready,
                     "Whether the pipeline the next render needs is compiled (else that render compiles it "
                     "first: seconds on lavapipe with a cold Mesa shader cache).")
        .def_prop_ro("samples", &px::Session::samples, "Samples per pixel accumulated (cheap: no "
                     "download, unlike stats()).")
        .def_prop_ro("converged", &px::Session::converged,
                     "Adaptive sampling found every pixel converged: render() adds nothing more (cheap). "
                     "stats()['adaptive_active_pixels'] counts the pixels still sampled.")
        .def("reset", &px::Session::reset, nb::call_guard<nb::gil_scoped_release>())
        .def("guiding_mixture",
             [](px::Session& s, nb::ndarray<const double, nb::c_contig, nb::device::cpu> point) {
                 const auto* guiding = dynamic_cast<const px::Guiding*>(s.technique("guiding"));
                 const px::guiding::GuidingField* f = guiding ? guiding->host_field() : nullptr;
                 if (!f) throw std::invalid_argument("guiding_mixture needs guiding on with guiding_fit = cpu");
                 return guiding_mixture_at(*f, point);
             }, "point"_a,
             "The guiding region holding `point` and its mixture (weights, mus, kappas, distances, pivot; "
             "region, fits, min, max), as the host fit (guiding_fit = cpu) last made it.")
        .def("stats",
             [](px::Session& s) {
                 px::SessionStats st;
                 {
                     nb::gil_scoped_release release;
                     st = s.stats();
                 }
                 nb::dict d;
                 d["samples"] = st.samples;
                 d["rays"] = st.rays;
                 d["fallback_samples"] = st.fallback_samples;
                 d["fallback_milliseconds"] = st.fallback_milliseconds;
                 d["fallback_film"] = st.fallback_film;
                 d["milliseconds"] = st.milliseconds;
                 d["frames"] = st.frames;
                 d["blas_builds"] = st.blas_builds;
                 d["light_tree_nodes"] = st.light_tree_nodes;
                 d["contact_boxes"] = st.contact_boxes;
                 d["adaptive_active_pixels"] = st.adaptive_active_pixels;
                 for (const auto& [name, value] : st.techniques)
                     std::visit([&, &name = name](const auto& v) { d[name.c_str()] = v; }, value);
                 d["device"] = s.device().name;
                 return d;
             })
        .def_static("pass_names",
                    [] {
                        std::vector<std::string> names;
                        for (const auto& p : px::passes()) names.push_back(p.name);
                        return names;
                    })
        .def("_test_sampling",
             [](px::Session& s, uint32_t routine, std::vector<float> params, uint32_t count, uint32_t seed,
                std::vector<float> input) {
                 std::vector<float> out;
                 {
                     nb::gil_scoped_release release;
                     out = s.test_sampling(routine, params, count, seed, input);
                 }
                 return to_numpy(std::move(out), {count, 2, 4});
             },
             "routine"_a, "params"_a, "count"_a, "seed"_a = 0, "input"_a = std::vector<float>())
        .def_prop_ro("width", &px::Session::width)
        .def_prop_ro("height", &px::Session::height)
        .def_prop_ro("device", [](px::Session& s) { return s.device().name; })
        .def_prop_ro("device_type", [](px::Session& s) { return s.device().type; })
        .def_prop_ro("triangle_count", &px::Session::triangle_count);
}
