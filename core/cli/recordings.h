/* vmac recordings, vmac recording get / to-test (recordings.c). Each
 * returns the exit code. */
#ifndef VMAC_CLI_RECORDINGS_H
#define VMAC_CLI_RECORDINGS_H

int vmac_recordings_main(int argc, char **argv);
int vmac_recording_main(int argc, char **argv);
int vmac_record_main(int argc, char **argv);

#endif
