#include "server/error_calibrator.hpp"

#include "renderer/model/camera.hpp"
#include "renderer/model/image.hpp"
#include "renderer/reference/reference_renderer.hpp"
#include "server/frame_encoder.hpp"

#include <spdlog/spdlog.h>
#include <turbojpeg.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <thread>

namespace volcast::server {

namespace {
using Clock = std::chrono::steady_clock;
// The cubic reference prefilters the whole volume in double (8 bytes a voxel) before its first ray.
constexpr size_t kMaxCubicReferenceVoxels = size_t(256) * 256 * 256;
} // namespace

Rgb8 toRgb8(const Image &image) { return {image.width, image.height, toRgb8OverBlack(image)}; }

Rgb8 decodeJpegRgb8(const std::vector<uint8_t> &jpeg) {
    // The frames frame_encoder.cpp wrote, decoded as a browser would: fancy upsampling and the
    // accurate integer inverse DCT, TurboJPEG's defaults. One decompressor per thread, kept.
    struct Decompressor {
        tjhandle handle = tjInitDecompress();
        ~Decompressor() {
            if (handle) tjDestroy(handle);
        }
    };
    thread_local Decompressor d;
    if (!d.handle) throw std::runtime_error("decoding a frame: " + std::string(tjGetErrorStr2(nullptr)));
    int width = 0, height = 0, subsampling = 0, colourSpace = 0;
    if (tjDecompressHeader3(d.handle, jpeg.data(), jpeg.size(), &width, &height, &subsampling, &colourSpace) != 0)
        throw std::runtime_error("decoding a frame: " + std::string(tjGetErrorStr2(d.handle)));
    Rgb8 out{width, height, std::vector<uint8_t>(size_t(width) * size_t(height) * 3)};
    if (tjDecompress2(d.handle, jpeg.data(), jpeg.size(), out.rgb.data(), width, 0, height, TJPF_RGB,
                      TJFLAG_ACCURATEDCT) != 0)
        throw std::runtime_error("decoding a frame: " + std::string(tjGetErrorStr2(d.handle)));
    return out;
}

Rgb8 scaledRgb8(Rgb8 image, int width, int height) {
    if (image.width == width && image.height == height) return image;
    // Through the renderer's own bilinear scaling (resizeBilinear), on floats of the bytes.
    Image from(image.width, image.height);
    for (size_t p = 0; p < size_t(image.width) * size_t(image.height); ++p)
        for (size_t c = 0; c < 3; ++c) from.rgba[p * 4 + c] = float(image.rgb[p * 3 + c]);
    const Image to = resizeBilinear(from, width, height);
    Rgb8 out{width, height, std::vector<uint8_t>(size_t(width) * size_t(height) * 3)};
    for (size_t p = 0; p < size_t(width) * size_t(height); ++p)
        for (size_t c = 0; c < 3; ++c) out.rgb[p * 3 + c] = uint8_t(std::lround(std::clamp(to.rgba[p * 4 + c], 0.0f, 255.0f)));
    return out;
}

double rmseRgb8(const Rgb8 &a, const Rgb8 &b) {
    if (a.width != b.width || a.height != b.height || a.rgb.size() != b.rgb.size())
        throw std::invalid_argument("images of different sizes compared");
    if (a.rgb.empty()) return 0;
    double sum = 0;
    for (size_t i = 0; i < a.rgb.size(); ++i) {
        const double d = (double(a.rgb[i]) - double(b.rgb[i])) / 255.0;
        sum += d * d;
    }
    return std::sqrt(sum / double(a.rgb.size()));
}

std::optional<protocol::ErrorEstimate> ErrorCalibrator::estimate(const std::string &key, int level, bool final) const {
    std::lock_guard lock(mutex_);
    auto it = measured_.find(key);
    if (it == measured_.end()) return std::nullopt;
    const Measured &m = it->second;
    if (final) return m.final;
    if (level < 0 || size_t(level) >= m.count.size() || m.count[size_t(level)] == 0) return std::nullopt;
    return protocol::ErrorEstimate{m.sum[size_t(level)] / m.count[size_t(level)], "rmse_rgb8_vs_final"};
}

void ErrorCalibrator::record(const std::string &key, int level, double rmse, size_t levels) {
    std::lock_guard lock(mutex_);
    if (!measured_.count(key) && measured_.size() >= kMaxKeys) measured_.clear();
    Measured &m = measured_[key];
    if (m.count.size() < levels) {
        m.count.resize(levels, 0);
        m.sum.resize(levels, 0);
    }
    m.sum[size_t(level)] += rmse;
    ++m.count[size_t(level)];
}

ErrorCalibrator::LevelsMeasured ErrorCalibrator::levels(const std::string &key, size_t levels) const {
    LevelsMeasured out{std::vector<std::optional<double>>(levels), std::vector<double>(levels, 0)};
    std::lock_guard lock(mutex_);
    auto it = measured_.find(key);
    if (it == measured_.end()) return out;
    const Measured &m = it->second;
    for (size_t l = 0; l < levels && l < m.count.size(); ++l)
        if (m.count[l] > 0) out.errors[l] = m.sum[l] / m.count[l];
    for (size_t l = 0; l < levels && l < m.backgroundMsPerSample.size(); ++l)
        out.backgroundMsPerSample[l] = m.backgroundMsPerSample[l];
    return out;
}

void ErrorCalibrator::finalRendered(std::shared_ptr<const CalibrationView> view,
                                    std::vector<std::pair<int, std::vector<uint8_t>>> levels, Rgb8 final,
                                    uint64_t viewSerial) {
    if (!enabled_) return;
    const size_t ladderSize = view->ladder.size();
    using Levels = std::vector<std::pair<int, std::vector<uint8_t>>>;
    auto shared = std::make_shared<std::pair<Levels, Rgb8>>(std::move(levels), std::move(final));
    // Once per kind of view (the worker runs a key once): every level, before the delivered ones.
    if (ladderSize > 1)
        worker_.request("levels of " + view->key, PreprocessWorker::Priority::Calibration,
                        [this, view, shared](const std::atomic<bool> &cancelled) {
                            calibrateLevels(*view, shared->second, cancelled);
                        });
    if (!shared->first.empty()) {
        worker_.request("levels " + std::to_string(viewSerial), PreprocessWorker::Priority::Calibration,
                        [this, key = view->key, shared, ladderSize](const std::atomic<bool> &) {
                            for (const auto &[level, jpeg] : shared->first) {
                                if (size_t(level) + 1 >= ladderSize) continue;
                                try {
                                    const Rgb8 &finalImage = shared->second;
                                    // As the client shows it: scaled up to the view where the level cast fewer rays.
                                    record(key, level,
                                           rmseRgb8(scaledRgb8(decodeJpegRgb8(jpeg), finalImage.width, finalImage.height),
                                                    finalImage),
                                           ladderSize);
                                } catch (const std::exception &e) {
                                    spdlog::warn("error calibration: level {} not measured: {}", level, e.what());
                                }
                            }
                        });
    }
    worker_.request("final " + view->key, PreprocessWorker::Priority::Calibration,
                    [this, view](const std::atomic<bool> &cancelled) { calibrateFinal(*view, cancelled); });
}

void ErrorCalibrator::calibrateLevels(const CalibrationView &view, const Rgb8 &final,
                                      const std::atomic<bool> &cancelled) {
    const auto t0 = Clock::now();
    const size_t count = view.ladder.size();
    std::vector<double> costs(count, 0);
    size_t done = 0;
    double waited = 0;
    for (size_t l = 0; l + 1 < count; ++l) {
        while (dragging_ && dragging_() && !cancelled && waited < kLevelsWaitSeconds) {
            std::this_thread::sleep_for(std::chrono::duration<double>(kPollSeconds));
            waited += kPollSeconds;
        }
        const double rendering = std::chrono::duration<double>(Clock::now() - t0).count() - waited;
        if (cancelled || waited >= kLevelsWaitSeconds || rendering > kLevelsBudgetSeconds) break;
        const Level &level = view.ladder[l];
        try {
            const auto t = Clock::now();
            // Its rays alone, as the scheduler sends the level (the whole grid as the window: not
            // upsampled), then scaled up to the view as the client shows it.
            const RayWindow grid{0, 0, raysForScale(view.width, level.quality.imageScale),
                                 raysForScale(view.height, level.quality.imageScale)};
            const Image image = view.renderer->render({view.transferFunction, view.camera, view.width, view.height,
                                                      level.quality, view.clipPlanes, grid});
            const double ms = std::chrono::duration<double, std::milli>(Clock::now() - t).count();
            const double rmse = rmseRgb8(scaledRgb8(decodeJpegRgb8(encodeJpeg(image, level.jpegQuality)), final.width, final.height), final);
            record(view.key, int(l), rmse, count);
            costs[l] = ms / std::max(1.0, predictedSamples(view.renderer->volume(), level.quality, view.width,
                                                           view.height));
            spdlog::debug("error calibration: level {} ({}): RMSE {:.4f}, {:.1f} ms in the background", l,
                          qualityToJson(level.quality).dump(), rmse, ms);
            ++done;
        } catch (const std::exception &e) {
            spdlog::warn("error calibration: level {} not rendered: {}", l, e.what());
        }
    }
    {
        std::lock_guard lock(mutex_);
        if (!measured_.count(view.key) && measured_.size() >= kMaxKeys) measured_.clear();
        measured_[view.key].backgroundMsPerSample = std::move(costs);
    }
    spdlog::debug("calibrated {} of {} levels in {:.0f} ms", done, count - 1,
                  std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
}

void ErrorCalibrator::calibrateFinal(const CalibrationView &view, const std::atomic<bool> &cancelled) {
    const auto t0 = Clock::now();
    const int w = view.width >= view.height ? kSide
                                            : std::max(4, int(std::lround(kSide * double(view.width) / view.height)));
    const int h = view.width >= view.height ? std::max(4, int(std::lround(kSide * double(view.height) / view.width)))
                                            : kSide;
    const Level &last = view.ladder.back();
    const Quality &fq = last.quality;
    const Volume &volume = view.renderer->volume();
    const Image fast = view.renderer->render({view.transferFunction, view.camera, w, h, fq, view.clipPlanes});

    // The exact integral, ray by ray, within the budget.
    std::optional<Image> reference;
    const bool cubic = fq.interpolation == Interpolation::Cubic;
    if (!cubic || volume.voxelCount() <= kMaxCubicReferenceVoxels) {
        ReferenceRenderer exact(volume, view.transferFunction, cubic ? Reconstruction::Cubic : Reconstruction::Linear);
        exact.setQuality(fq); // shading, compositing (MIP), crop
        const RayGenerator rays(view.camera, w, h);
        Image image(w, h);
        bool inTime = true;
        for (int y = 0; y < h && inTime; ++y) {
            for (int x = 0; x < w; ++x) {
                const RayIntegral r = exact.integrate(rays.pixelRay(x, y), view.clipPlanes, kReferenceTolerance);
                float *px = image.pixel(x, y);
                px[0] = float(r.color.r);
                px[1] = float(r.color.g);
                px[2] = float(r.color.b);
                px[3] = float(r.color.a);
            }
            if (cancelled) return;
            inTime = std::chrono::duration<double>(Clock::now() - t0).count() < kReferenceBudgetSeconds;
        }
        if (inTime) reference = std::move(image);
    }
    std::string method;
    if (reference) {
        method = "rmse_rgb8_vs_reference_" + std::to_string(kSide) + "px";
    } else {
        if (cancelled) return;
        Quality fine = fq;
        fine.step = fq.step / 4;
        fine.jitter = false;
        fine.earlyTermination = std::max(fq.earlyTermination, 0.999);
        reference = view.renderer->render({view.transferFunction, view.camera, w, h, fine, view.clipPlanes});
        method = "rmse_rgb8_vs_quarter_step_" + std::to_string(kSide) + "px";
    }
    const double rmse = rmseRgb8(toRgb8(fast), toRgb8(*reference));
    {
        std::lock_guard lock(mutex_);
        if (!measured_.count(view.key) && measured_.size() >= kMaxKeys) measured_.clear();
        measured_[view.key].final = protocol::ErrorEstimate{rmse, method};
    }
    spdlog::debug("calibrated the final level ({}) in {:.0f} ms", method,
                  std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
}

} // namespace volcast::server
