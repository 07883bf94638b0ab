/*
 * LD_PRELOAD shim for Debian's user-mode-linux on hosts with a large XSAVE area.
 *
 * UML 6.1 hands ptrace(PTRACE_[GS]ETREGSET, NT_X86_XSTATE) a fixed 2696-byte buffer. Hosts
 * with AMX or CET state have an XSAVE area of ~11 KB and refuse the short buffer (EFAULT), so
 * the guest's init dies with "ptrace set fp regs failed, errno = 14". This shim passes the
 * kernel a buffer larger than any XSAVE area, carrying UML's bytes, and clears the XSTATE_BV
 * bits of components that lie beyond UML's buffer so they are restored to their init state.
 * (Forcing the older FXSAVE path instead silently corrupts vector registers.)
 */
#define _GNU_SOURCE
#include <cpuid.h>
#include <dlfcn.h>
#include <stdarg.h>
#include <stdint.h>
#include <string.h>
#include <sys/ptrace.h>
#include <sys/types.h>
#include <sys/uio.h>

#ifndef NT_X86_XSTATE
#define NT_X86_XSTATE 0x202
#endif
#define WIDE_BYTES 32768
#define XSTATE_BV_OFFSET 512
#define XSAVE_MIN_BYTES 576

typedef long (*ptrace_fn)(int, pid_t, void *, void *);
static ptrace_fn real_ptrace;
static __thread unsigned char wide[WIDE_BYTES] __attribute__((aligned(64)));

/* Drop components whose (offset, size) from CPUID leaf 0xD do not fit in `len` bytes. */
static void clear_components_beyond(unsigned char *buf, size_t len) {
    uint64_t bv;
    memcpy(&bv, buf + XSTATE_BV_OFFSET, sizeof bv);
    for (unsigned i = 2; i < 64; i++) {
        unsigned size, offset, ecx, edx;
        if (!(bv & (1ULL << i))) continue;
        __cpuid_count(0xd, i, size, offset, ecx, edx);
        if (size == 0 || (size_t)offset + size > len) bv &= ~(1ULL << i);
    }
    memcpy(buf + XSTATE_BV_OFFSET, &bv, sizeof bv);
}

long ptrace(enum __ptrace_request req, ...) {
    va_list ap;
    va_start(ap, req);
    pid_t pid = va_arg(ap, pid_t);
    void *addr = va_arg(ap, void *);
    void *data = va_arg(ap, void *);
    va_end(ap);
    if (!real_ptrace) real_ptrace = (ptrace_fn)dlsym(RTLD_NEXT, "ptrace");

    int is_xstate = (req == PTRACE_GETREGSET || req == PTRACE_SETREGSET) &&
                    (uintptr_t)addr == NT_X86_XSTATE && data;
    if (!is_xstate) return real_ptrace(req, pid, addr, data);

    struct iovec *iov = data;
    if (iov->iov_len < XSAVE_MIN_BYTES || iov->iov_len >= WIDE_BYTES)
        return real_ptrace(req, pid, addr, data);

    struct iovec wide_iov = {wide, WIDE_BYTES};
    if (req == PTRACE_SETREGSET) {
        memset(wide, 0, WIDE_BYTES);
        memcpy(wide, iov->iov_base, iov->iov_len);
        clear_components_beyond(wide, iov->iov_len);
        return real_ptrace(req, pid, addr, &wide_iov);
    }
    long r = real_ptrace(req, pid, addr, &wide_iov);
    if (r == 0) {
        size_t n = wide_iov.iov_len < iov->iov_len ? wide_iov.iov_len : iov->iov_len;
        clear_components_beyond(wide, n);
        memcpy(iov->iov_base, wide, n);
        iov->iov_len = n;
    }
    return r;
}
