"""Preloaded in the local executor's fork server (multiprocessing imports it there when the server
starts): the server is killed by the kernel the moment the process that started it dies, and with it
(PR_SET_PDEATHSIG in each worker) every worker, so nothing of a killed export or eval goes on running.
Only the kernel request is made here: the fork server must stay single-threaded."""

from teleprev.corpus.executor import die_with_parent

die_with_parent()
