/*
 * rendiff's llvmpipe peer: one shaded frame of a triangle mesh by Mesa's
 * llvmpipe (OpenGL 3.3 core on a surfaceless EGL display, into a
 * colour+depth framebuffer object), timed frame by frame.
 *
 *   frame INPUT FRAMES OUT_PREFIX
 *
 * INPUT is the file rendiff-peers writes (peers/src/llvmpipe.rs: the
 * layout is read below, every value little-endian). The mesh is uploaded
 * once; then FRAMES frames are drawn, each one glClear + glDrawElements +
 * glFinish, timed with CLOCK_MONOTONIC. After the timed frames (untimed):
 * the shaded frame is read back into OUT_PREFIX.rgba, and one more frame
 * with a shader that writes gl_PrimitiveID + 1 into OUT_PREFIX.id (both
 * width x height RGBA8, bottom row first), so the caller can check that
 * both renderers drew the same triangles at the same pixels.
 *
 * stdout: "renderer: ...", "frame_ms: WALL CPU" per frame (CLOCK_MONOTONIC
 * and the process's CPU time, CLOCK_PROCESS_CPUTIME_ID), "threads: N
 * (names)" (of this process, after the frames), "covered: K" (pixels of
 * the shaded frame with alpha 1). Exit status 3 when the renderer is not llvmpipe.
 */
#define _POSIX_C_SOURCE 199309L
#define GL_GLEXT_PROTOTYPES 1
#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GL/glcorearb.h>
#include <dirent.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static void die(const char *what) {
    fprintf(stderr, "llvmpipe frame: %s\n", what);
    exit(1);
}

static void check_gl(const char *where) {
    GLenum e = glGetError();
    if (e != GL_NO_ERROR) {
        fprintf(stderr, "llvmpipe frame: GL error 0x%x at %s\n", e, where);
        exit(1);
    }
}

static void read_exact(FILE *f, void *p, size_t n) {
    if (fread(p, 1, n, f) != n)
        die("the input file is shorter than its header says");
}

static GLuint shader(GLenum kind, const char *src) {
    GLuint s = glCreateShader(kind);
    glShaderSource(s, 1, &src, NULL);
    glCompileShader(s);
    GLint ok = 0;
    glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
    if (!ok) {
        char log[4096];
        glGetShaderInfoLog(s, sizeof log, NULL, log);
        fprintf(stderr, "llvmpipe frame: shader: %s\n", log);
        exit(1);
    }
    return s;
}

static GLuint program(const char *vs, const char *fs) {
    GLuint p = glCreateProgram();
    glAttachShader(p, shader(GL_VERTEX_SHADER, vs));
    glAttachShader(p, shader(GL_FRAGMENT_SHADER, fs));
    glBindAttribLocation(p, 0, "position");
    glBindAttribLocation(p, 1, "normal");
    glLinkProgram(p);
    GLint ok = 0;
    glGetProgramiv(p, GL_LINK_STATUS, &ok);
    if (!ok) {
        char log[4096];
        glGetProgramInfoLog(p, sizeof log, NULL, log);
        fprintf(stderr, "llvmpipe frame: link: %s\n", log);
        exit(1);
    }
    return p;
}

static const char *VS =
    "#version 330 core\n"
    "uniform mat4 view_proj;\n"
    "in vec3 position;\n"
    "in vec3 normal;\n"
    "out vec3 p_world;\n"
    "out vec3 n_world;\n"
    "void main() {\n"
    "    p_world = position;\n"
    "    n_world = normal;\n"
    "    gl_Position = view_proj * vec4(position, 1.0);\n"
    "}\n";

/* rendiff's local shading of one opaque material under one light
 * (crates/rendiff-core/src/shade.rs): pigment·ambient·A_g + pigment·light
 * ·diffuse·(N·L) + light·phong·(R·L)^phong_size, with the smooth normal
 * flipped toward the viewer and R the view direction reflected about it.
 * The caller passes the products as three colours (ks = 0: no highlight,
 * as for rendiff's shadowless lights). */
static const char *FS_SHADE =
    "#version 330 core\n"
    "uniform vec3 eye;\n"
    "uniform vec3 light_pos;\n"
    "uniform vec3 ka;\n"
    "uniform vec3 kd;\n"
    "uniform vec3 ks;\n"
    "uniform float phong_size;\n"
    "in vec3 p_world;\n"
    "in vec3 n_world;\n"
    "out vec4 color;\n"
    "void main() {\n"
    "    vec3 d = normalize(p_world - eye);\n"
    "    vec3 n = normalize(n_world);\n"
    "    if (dot(n, d) > 0.0) n = -n;\n"
    "    vec3 l = normalize(light_pos - p_world);\n"
    "    float ndl = dot(n, l);\n"
    "    vec3 c = ka;\n"
    "    if (ndl > 0.0) {\n"
    "        c += kd * ndl;\n"
    "        float rl = dot(reflect(d, n), l);\n"
    "        if (rl > 0.0) c += ks * pow(rl, phong_size);\n"
    "    }\n"
    "    color = vec4(c, 1.0);\n"
    "}\n";

static const char *FS_ID =
    "#version 330 core\n"
    "out vec4 color;\n"
    "void main() {\n"
    "    uint k = uint(gl_PrimitiveID) + 1u;\n"
    "    color = vec4(float(k & 255u), float((k >> 8) & 255u),\n"
    "                 float((k >> 16) & 255u), float((k >> 24) & 255u)) / 255.0;\n"
    "}\n";

/* "threads: N (name, name, ...)": the threads of this process. */
static void print_threads(void) {
    DIR *d = opendir("/proc/self/task");
    if (!d) {
        printf("threads: ?\n");
        return;
    }
    char names[1024] = "";
    int n = 0;
    struct dirent *e;
    while ((e = readdir(d)) != NULL) {
        if (e->d_name[0] == '.')
            continue;
        n++;
        char path[300], comm[64] = "?";
        snprintf(path, sizeof path, "/proc/self/task/%s/comm", e->d_name);
        FILE *f = fopen(path, "r");
        if (f) {
            if (fgets(comm, sizeof comm, f))
                comm[strcspn(comm, "\n")] = 0;
            fclose(f);
        }
        size_t len = strlen(names);
        snprintf(names + len, sizeof names - len, "%s%s", n > 1 ? ", " : "", comm);
    }
    closedir(d);
    printf("threads: %d (%s)\n", n, names);
}

static double ms_of(clockid_t clock) {
    struct timespec t;
    clock_gettime(clock, &t);
    return (double)t.tv_sec * 1e3 + (double)t.tv_nsec * 1e-6;
}

static void write_file(const char *prefix, const char *ext, const void *p, size_t n) {
    char path[4096];
    snprintf(path, sizeof path, "%s%s", prefix, ext);
    FILE *f = fopen(path, "wb");
    if (!f || fwrite(p, 1, n, f) != n || fclose(f) != 0)
        die("could not write the read-back frame");
}

int main(int argc, char **argv) {
    if (argc != 4)
        die("usage: frame INPUT FRAMES OUT_PREFIX");
    int frames = atoi(argv[2]);
    if (frames < 1)
        die("FRAMES must be at least 1");

    /* The input: magic, sizes, matrices and colours, then the mesh. */
    FILE *f = fopen(argv[1], "rb");
    if (!f)
        die("could not open the input file");
    char magic[8];
    read_exact(f, magic, 8);
    if (memcmp(magic, "RDLLVMP1", 8) != 0)
        die("the input file is not a rendiff-peers llvmpipe input (bad magic)");
    uint32_t width, height, nverts, ntris;
    float view_proj[16], eye[3], light_pos[3], ka[3], kd[3], ks[3], phong_size;
    read_exact(f, &width, 4);
    read_exact(f, &height, 4);
    read_exact(f, &nverts, 4);
    read_exact(f, &ntris, 4);
    read_exact(f, view_proj, sizeof view_proj);
    read_exact(f, eye, sizeof eye);
    read_exact(f, light_pos, sizeof light_pos);
    read_exact(f, ka, sizeof ka);
    read_exact(f, kd, sizeof kd);
    read_exact(f, ks, sizeof ks);
    read_exact(f, &phong_size, 4);
    if (width == 0 || height == 0 || width > 16384 || height > 16384)
        die("frame size out of range");
    size_t vbytes = (size_t)nverts * 6 * sizeof(float);
    size_t ibytes = (size_t)ntris * 3 * sizeof(uint32_t);
    float *verts = malloc(vbytes);
    uint32_t *idx = malloc(ibytes);
    if (!verts || !idx)
        die("out of memory");
    read_exact(f, verts, vbytes);
    read_exact(f, idx, ibytes);
    fclose(f);
    for (size_t i = 0; i < (size_t)ntris * 3; i++)
        if (idx[i] >= nverts)
            die("a triangle index is out of range");

    /* A surfaceless EGL display and an OpenGL 3.3 core context. */
    PFNEGLGETPLATFORMDISPLAYEXTPROC get_display =
        (PFNEGLGETPLATFORMDISPLAYEXTPROC)eglGetProcAddress("eglGetPlatformDisplayEXT");
    if (!get_display)
        die("EGL has no eglGetPlatformDisplayEXT");
    EGLDisplay dpy = get_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, NULL);
    EGLint major, minor;
    if (dpy == EGL_NO_DISPLAY || !eglInitialize(dpy, &major, &minor))
        die("no surfaceless EGL display (EGL_MESA_platform_surfaceless)");
    if (!eglBindAPI(EGL_OPENGL_API))
        die("EGL cannot bind the OpenGL API");
    const EGLint config_attrs[] = {EGL_SURFACE_TYPE, EGL_PBUFFER_BIT, EGL_RENDERABLE_TYPE,
                                   EGL_OPENGL_BIT, EGL_NONE};
    EGLConfig config = NULL;
    EGLint nconfig = 0;
    if (!eglChooseConfig(dpy, config_attrs, &config, 1, &nconfig) || nconfig < 1)
        config = NULL; /* EGL_KHR_no_config_context */
    const EGLint ctx_attrs[] = {EGL_CONTEXT_MAJOR_VERSION, 3, EGL_CONTEXT_MINOR_VERSION, 3,
                                EGL_CONTEXT_OPENGL_PROFILE_MASK,
                                EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT, EGL_NONE};
    EGLContext ctx = eglCreateContext(dpy, config, EGL_NO_CONTEXT, ctx_attrs);
    if (ctx == EGL_NO_CONTEXT)
        die("could not create an OpenGL 3.3 core context");
    if (!eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, ctx))
        die("could not make the context current without a surface");

    const char *renderer = (const char *)glGetString(GL_RENDERER);
    printf("renderer: %s\n", renderer ? renderer : "(none)");
    printf("version: %s\n", (const char *)glGetString(GL_VERSION));
    fflush(stdout);
    if (!renderer || strstr(renderer, "llvmpipe") == NULL) {
        fprintf(stderr, "llvmpipe frame: the renderer is %s, not llvmpipe\n",
                renderer ? renderer : "(none)");
        return 3;
    }

    /* The framebuffer: RGBA8 colour and 24-bit depth. */
    GLuint fbo, rb[2];
    glGenFramebuffers(1, &fbo);
    glBindFramebuffer(GL_FRAMEBUFFER, fbo);
    glGenRenderbuffers(2, rb);
    glBindRenderbuffer(GL_RENDERBUFFER, rb[0]);
    glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, (GLsizei)width, (GLsizei)height);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, rb[0]);
    glBindRenderbuffer(GL_RENDERBUFFER, rb[1]);
    glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, (GLsizei)width, (GLsizei)height);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, rb[1]);
    if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
        die("the framebuffer is incomplete");
    glViewport(0, 0, (GLsizei)width, (GLsizei)height);

    /* The mesh, uploaded once: interleaved position and normal, indices. */
    GLuint vao, buf[2];
    glGenVertexArrays(1, &vao);
    glBindVertexArray(vao);
    glGenBuffers(2, buf);
    glBindBuffer(GL_ARRAY_BUFFER, buf[0]);
    glBufferData(GL_ARRAY_BUFFER, (GLsizeiptr)vbytes, verts, GL_STATIC_DRAW);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 6 * sizeof(float), (void *)0);
    glEnableVertexAttribArray(1);
    glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, 6 * sizeof(float),
                          (void *)(3 * sizeof(float)));
    glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, buf[1]);
    glBufferData(GL_ELEMENT_ARRAY_BUFFER, (GLsizeiptr)ibytes, idx, GL_STATIC_DRAW);
    free(verts);
    free(idx);
    check_gl("upload");

    GLuint shade = program(VS, FS_SHADE);
    GLuint ids = program(VS, FS_ID);
    glUseProgram(shade);
    glUniformMatrix4fv(glGetUniformLocation(shade, "view_proj"), 1, GL_FALSE, view_proj);
    glUniform3fv(glGetUniformLocation(shade, "eye"), 1, eye);
    glUniform3fv(glGetUniformLocation(shade, "light_pos"), 1, light_pos);
    glUniform3fv(glGetUniformLocation(shade, "ka"), 1, ka);
    glUniform3fv(glGetUniformLocation(shade, "kd"), 1, kd);
    glUniform3fv(glGetUniformLocation(shade, "ks"), 1, ks);
    glUniform1f(glGetUniformLocation(shade, "phong_size"), phong_size);
    glUseProgram(ids);
    glUniformMatrix4fv(glGetUniformLocation(ids, "view_proj"), 1, GL_FALSE, view_proj);
    check_gl("uniforms");

    /* Depth test, back faces (clockwise in window coordinates) culled. */
    glEnable(GL_DEPTH_TEST);
    glDepthFunc(GL_LESS);
    glEnable(GL_CULL_FACE);
    glCullFace(GL_BACK);
    glFrontFace(GL_CCW);
    glClearColor(0.0f, 0.0f, 0.0f, 0.0f);
    glClearDepth(1.0);
    glFinish();

    /* The timed frames. */
    glUseProgram(shade);
    for (int i = 0; i < frames; i++) {
        double t0 = ms_of(CLOCK_MONOTONIC), c0 = ms_of(CLOCK_PROCESS_CPUTIME_ID);
        glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
        glDrawElements(GL_TRIANGLES, (GLsizei)(ntris * 3), GL_UNSIGNED_INT, (void *)0);
        glFinish();
        double t1 = ms_of(CLOCK_MONOTONIC), c1 = ms_of(CLOCK_PROCESS_CPUTIME_ID);
        printf("frame_ms: %.3f %.3f\n", t1 - t0, c1 - c0);
    }
    print_threads();
    check_gl("frames");

    /* Untimed: the shaded frame, then the triangle ids. */
    size_t pixels = (size_t)width * height;
    unsigned char *rgba = malloc(pixels * 4);
    if (!rgba)
        die("out of memory");
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glReadPixels(0, 0, (GLsizei)width, (GLsizei)height, GL_RGBA, GL_UNSIGNED_BYTE, rgba);
    size_t covered = 0;
    for (size_t i = 0; i < pixels; i++)
        covered += rgba[4 * i + 3] != 0;
    printf("covered: %zu\n", covered);
    write_file(argv[3], ".rgba", rgba, pixels * 4);

    glUseProgram(ids);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    glDrawElements(GL_TRIANGLES, (GLsizei)(ntris * 3), GL_UNSIGNED_INT, (void *)0);
    glReadPixels(0, 0, (GLsizei)width, (GLsizei)height, GL_RGBA, GL_UNSIGNED_BYTE, rgba);
    check_gl("read-back");
    write_file(argv[3], ".id", rgba, pixels * 4);
    free(rgba);

    eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    eglDestroyContext(dpy, ctx);
    eglTerminate(dpy);
    return 0;
}
