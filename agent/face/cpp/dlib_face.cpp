// The C face of dlib for agent-face (src/ffi.rs): the 68-point shape predictor and the ResNet face descriptor,
// loaded from their .dat files and run on a borrowed 8-bit grey frame. Every entry point catches every C++
// exception and reports it as a message, since an exception must not cross into Rust.

#include <dlib/dnn.h>
#include <dlib/image_processing.h>
#include <dlib/image_transforms.h>

#include <cstdint>
#include <cstring>
#include <exception>
#include <string>

namespace {

using namespace dlib;

// The network of dlib_face_recognition_resnet_model_v1.dat, as dlib's dnn_face_recognition_ex.cpp declares it: a
// ResNet-29 whose last layer gives a 128-dimensional descriptor; two faces of one person lie within 0.6.
template <template <int, template <typename> class, int, typename> class block, int N,
          template <typename> class BN, typename SUBNET>
using residual = add_prev1<block<N, BN, 1, tag1<SUBNET>>>;

template <template <int, template <typename> class, int, typename> class block, int N,
          template <typename> class BN, typename SUBNET>
using residual_down = add_prev2<avg_pool<2, 2, 2, 2, skip1<tag2<block<N, BN, 2, tag1<SUBNET>>>>>>;

template <int N, template <typename> class BN, int stride, typename SUBNET>
using block = BN<con<N, 3, 3, 1, 1, relu<BN<con<N, 3, 3, stride, stride, SUBNET>>>>>;

template <int N, typename SUBNET> using ares = relu<residual<block, N, affine, SUBNET>>;
template <int N, typename SUBNET> using ares_down = relu<residual_down<block, N, affine, SUBNET>>;

template <typename SUBNET> using alevel0 = ares_down<256, SUBNET>;
template <typename SUBNET> using alevel1 = ares<256, ares<256, ares_down<256, SUBNET>>>;
template <typename SUBNET> using alevel2 = ares<128, ares<128, ares_down<128, SUBNET>>>;
template <typename SUBNET> using alevel3 = ares<64, ares<64, ares<64, ares_down<64, SUBNET>>>>;
template <typename SUBNET> using alevel4 = ares<32, ares<32, ares<32, SUBNET>>>;

using anet_type = loss_metric<fc_no_bias<128, avg_pool_everything<alevel0<alevel1<alevel2<alevel3<alevel4<
    max_pool<3, 3, 2, 2, relu<affine<con<32, 7, 7, 2, 2, input_rgb_image_sized<150>>>>>>>>>>>>>;

void report(const char* message, char* err, size_t err_len) {
    if (err == nullptr || err_len == 0) {
        return;
    }
    std::strncpy(err, message, err_len - 1);
    err[err_len - 1] = '\0';
}

// A borrowed grey frame copied into dlib's image type (a 640x360 frame is 230 kB: a few microseconds).
array2d<unsigned char> grey_image(const uint8_t* pixels, int32_t width, int32_t height, int32_t stride) {
    array2d<unsigned char> image(height, width);
    for (int32_t row = 0; row < height; ++row) {
        std::memcpy(&image[row][0], pixels + static_cast<size_t>(row) * stride, static_cast<size_t>(width));
    }
    return image;
}

// Runs `body`, which returns 0 or -1, and turns any exception into -1 with its message in `err`.
template <typename Body>
int guarded(Body body, char* err, size_t err_len) {
    try {
        return body();
    } catch (const std::exception& e) {
        report(e.what(), err, err_len);
    } catch (...) {
        report("unknown C++ exception", err, err_len);
    }
    return -1;
}

}  // namespace

struct FaceModels {
    shape_predictor landmarks;
    anet_type descriptor;
    bool has_descriptor = false;
};

extern "C" {

FaceModels* face_models_load(const char* landmarks_path, const char* descriptor_path, char* err, size_t err_len) {
    try {
        auto* models = new FaceModels();
        try {
            deserialize(landmarks_path) >> models->landmarks;
            if (models->landmarks.num_parts() != 68) {
                report("the landmark model does not give 68 points", err, err_len);
                delete models;
                return nullptr;
            }
            if (descriptor_path != nullptr) {
                deserialize(descriptor_path) >> models->descriptor;
                models->has_descriptor = true;
            }
        } catch (...) {
            delete models;
            throw;
        }
        return models;
    } catch (const std::exception& e) {
        report(e.what(), err, err_len);
    } catch (...) {
        report("unknown C++ exception", err, err_len);
    }
    return nullptr;
}

void face_models_free(FaceModels* models) { delete models; }

int face_landmarks(const FaceModels* models, const uint8_t* pixels, int32_t width, int32_t height, int32_t stride,
                   int32_t x, int32_t y, int32_t w, int32_t h, float* out_xy, char* err, size_t err_len) {
    return guarded(
        [&] {
            auto image = grey_image(pixels, width, height, stride);
            const rectangle box(x, y, x + w - 1, y + h - 1);
            const full_object_detection shape = models->landmarks(image, box);
            for (unsigned long i = 0; i < shape.num_parts(); ++i) {
                out_xy[2 * i] = static_cast<float>(shape.part(i).x());
                out_xy[2 * i + 1] = static_cast<float>(shape.part(i).y());
            }
            return 0;
        },
        err, err_len);
}

int face_descriptor(FaceModels* models, const uint8_t* pixels, int32_t width, int32_t height, int32_t stride,
                    const float* xy, float* out, char* err, size_t err_len) {
    return guarded(
        [&] {
            if (!models->has_descriptor) {
                report("no descriptor model was loaded", err, err_len);
                return -1;
            }
            auto image = grey_image(pixels, width, height, stride);
            std::vector<point> parts(68);
            for (size_t i = 0; i < 68; ++i) {
                parts[i] = point(static_cast<long>(xy[2 * i] + 0.5f), static_cast<long>(xy[2 * i + 1] + 0.5f));
            }
            const full_object_detection shape(get_rect(image), parts);
            // The chip the network was trained on: 150x150, aligned on the landmarks, with a quarter of padding.
            matrix<unsigned char> grey_chip;
            extract_image_chip(image, get_face_chip_details(shape, 150, 0.25), grey_chip);
            matrix<rgb_pixel> chip;
            assign_image(chip, grey_chip);
            const matrix<float, 0, 1> descriptor = models->descriptor(chip);
            for (long i = 0; i < 128; ++i) {
                out[i] = descriptor(i);
            }
            return 0;
        },
        err, err_len);
}

}  // extern "C"
