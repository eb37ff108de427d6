! The reading loop of uDALES's energy balance (src/initfac.f90, readfacetfiles, at
! uDALES commit 2fe4df1), written again for ffstream's tests: `export --udales` must
! write files this loop reads as they are.
!
! uDALES opens vfsparse.inp.NNN and reads it with a list-directed READ, exactly nnz
! times (nnz from namoptions), with no IOSTAT: a line that is not `i j F` (a `#`
! header, a missing value) stops the program with a run-time error. It then reads
! svf.inp.NNN: one header line as text, then nfcts sky view factors. uDALES builds
! with -fdefault-real-8, so REAL is 8 bytes there; here the reals are real(8).
!
! Usage: read_vfsparse VFSPARSE NNZ NFCTS SVF
! Prints `count N`, `sum_f S`, `sum_i I`, `sum_j J`, `svf_count N`, `sum_svf S`, one per
! line; exits 1 (after a message on stderr) when an index is outside 1..NFCTS or a
! value outside [0, 1]. A file the READ cannot parse ends the program with gfortran's
! run-time error (exit status 2), as it would end uDALES.
program read_vfsparse
  implicit none
  integer :: ifinput, nnz, nfcts, n
  integer, allocatable :: ivfsparse(:), jvfsparse(:)
  real(8), allocatable :: vfsparse(:), svf(:)
  character(len=4096) :: vfpath, svfpath, arg
  character(80) :: chmess

  if (command_argument_count() /= 4) then
    write (0, '(a)') 'usage: read_vfsparse VFSPARSE NNZ NFCTS SVF'
    stop 1
  end if
  call get_command_argument(1, vfpath)
  call get_command_argument(2, arg)
  read (arg, *) nnz
  call get_command_argument(3, arg)
  read (arg, *) nfcts
  call get_command_argument(4, svfpath)

  allocate (ivfsparse(1:nnz)); ivfsparse = 0
  allocate (jvfsparse(1:nnz)); jvfsparse = 0
  allocate (vfsparse(1:nnz)); vfsparse = 0.
  allocate (svf(1:nfcts)); svf = 0.

  ! As initfac.f90: list-directed, nnz times, no IOSTAT.
  open (newunit=ifinput, file=trim(vfpath), status='old', action='read')
  do n = 1, nnz
    read (ifinput, *) ivfsparse(n), jvfsparse(n), vfsparse(n)
  end do
  close (ifinput)

  ! As initfac.f90: one header line, then nfcts values.
  open (newunit=ifinput, file=trim(svfpath), status='old', action='read')
  read (ifinput, '(a80)') chmess
  do n = 1, nfcts
    read (ifinput, *) svf(n)
  end do
  close (ifinput)

  ! What modEB.f90 would index with: facets 1..nfcts, view factors in [0, 1].
  if (nnz > 0) then
    if (minval(ivfsparse) < 1 .or. maxval(ivfsparse) > nfcts .or. &
        minval(jvfsparse) < 1 .or. maxval(jvfsparse) > nfcts) then
      write (0, '(a)') 'read_vfsparse: a facet index is outside 1..nfcts'
      stop 1
    end if
    if (minval(vfsparse) < 0. .or. maxval(vfsparse) > 1.) then
      write (0, '(a)') 'read_vfsparse: a view factor is outside [0, 1]'
      stop 1
    end if
  end if
  if (minval(svf) < 0. .or. maxval(svf) > 1.) then
    write (0, '(a)') 'read_vfsparse: a sky view factor is outside [0, 1]'
    stop 1
  end if

  write (*, '(a, i0)') 'count ', nnz
  write (*, '(a, es24.16)') 'sum_f ', sum(vfsparse)
  write (*, '(a, i0)') 'sum_i ', sum(int(ivfsparse, 8))
  write (*, '(a, i0)') 'sum_j ', sum(int(jvfsparse, 8))
  write (*, '(a, i0)') 'svf_count ', nfcts
  write (*, '(a, es24.16)') 'sum_svf ', sum(svf)
end program read_vfsparse
