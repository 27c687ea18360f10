~VERSION INFORMATION
 VERS.                  1.2:   CWLS LOG ASCII STANDARD -VERSION 1.2
 WRAP.                  NO:   ONE LINE PER DEPTH STEP
~WELL INFORMATION BLOCK
 STRT.M        1670.000000:
 STOP.M        1660.000000:
 STEP.M            -0.1250:
 NULL.           -999.2500:
 COMP.             COMPANY:   # ANY OIL COMPANY LTD.
 WELL.                WELL:   ANY ET AL OIL WELL #12
 FLD .               FIELD:   EDAM
 LOC .            LOCATION:   A9-16-49-20W3M
 PROV.            PROVINCE:   SASKATCHEWAN
 SRVC.     SERVICE COMPANY:   ANY LOGGING COMPANY LTD.
 DATE.            LOG DATE:   25-DEC-1988
 UWI .      UNIQUE WELL ID:   100091604920W300
~CURVE INFORMATION
 ETIM.M                      :  1  DEPTH
 BSG1  .US/M                 :  2  SONIC TRANSIT TIME
 BQP1.K/M3                   :  3  BULK DENSITY
 POMS.V/V                    :  4   NEUTRON POROSITY
 POPV.OHMM                   :  5  RXO RESISTIVITY
 HMS1.OHMM                   :  6  SHALLOW RESISTIVITY
~PARAMETER INFORMATION
~Other
~ASCII Test Data
#   ETIM    BSG1    BQP1    POMS    POPV    HMS1
#--------------------------------------------------------
      0.300   2355.765    2343.880       0.000       0.000       0.000
      0.400   2355.765    2343.880       0.000       0.000       0.000
      0.500   2355.765    2343.880       0.000       0.000       0.000
      0.600   2355.765    2343.880       0.000       0.000       0.000
