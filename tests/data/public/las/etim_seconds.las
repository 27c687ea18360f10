~VERSION INFORMATION
 VERS.                       2.0    :   CWLS LOG ASCII STANDARD -VERSION 2.0
 WRAP.                       NO     :   ONE LINE PER TIME STEP
#
~WELL INFORMATION 
STRT    .S      0.0000                           :START TIME 
STOP    .S      39.9000                          :STOP TIME
STEP    .S      0.3000                           :STEP
NULL    .       -999.25                          :NULL VALUE
COMP    .       ANY OIL COMPANY INC.             :COMPANY
WELL    .       ANY ET 12-34-12-34               :WELL
FLD     .       WILDCAT                          :FIELD
LOC     .       12-34-12-34W5                    :LOCATION
PROV    .       ALBERTA                          :PROVINCE 
SRVC    .       ANY LOGGING COMPANY INC.         :SERVICE COMPANY
DATE    .       13-DEC-86                        :LOG DATE
UWI     .       100123401234W500                 :UNIQUE WELL ID
#
~CURVE INFORMATION
 ETIM   .S               :  1  ELAPSED TIME
 BFR1   .OHMM            :  2  SINGLE PROBE 1 RESISTIVITY
 BSG1   .PSIG            :  3  SINGLE PROBE 1 STRAIN GAUGE PRESSURE 
#
~PARAMETER INFORMATION
MRT    .DEGC            67.0    : BOTTOM HOLE TEMPERATURE
GDEPT  .M               3456.5  : GAUGE DEPTH
DFD    .KG/M3           1000.0  : MUD WEIGHT
#
~A
0.0000          0.2125          16564.1445
0.3000          0.2125          16564.1445
0.6000          0.2125          16564.2421
0.9000          0.2125          16564.0434
1.2000          0.2125          16564.0430
1.5000          0.2125          16564.0435
